//! Embree 3 as a ray-casting backend, for measuring our own BVH against (PRODUCT.md:
//! "our own BVH at ≥ 0.8× Embree's throughput on the same incoherent rays").
//!
//! Embree (Wald, Woop, Benthin, Johnson & Ernst 2014, "Embree: a kernel framework for
//! efficient CPU ray tracing") builds an SAH BVH4/BVH8 with SIMD node and triangle tests.
//! This crate declares, by hand, the dozen `rtc*` functions of `rtcore.h` (Embree 3.13) we
//! need — no bindgen, no headers at build time — and wraps them in a safe [`EmbreeScene`]
//! built from the same `[[Vec3; 3]]` triangle list as `radiosity::accel::Bvh`, answering
//! the same queries with the same conventions (t in units of the unnormalised direction,
//! `u, v` the barycentrics of v1 and v2, `prim` the index in the input).
//!
//! It is an optional dependency of the command-line program (`--features embree`) and is
//! never used by the library; `unsafe` is confined to this crate's FFI calls. Linking needs
//! `libembree3` (Debian: `apt-get install libembree-dev`).

use std::ffi::{c_char, c_int, c_uint, c_void, CString};

use glam::Vec3;

#[allow(non_camel_case_types)]
mod ffi {
    use super::*;

    pub type RTCDevice = *mut c_void;
    pub type RTCScene = *mut c_void;
    pub type RTCGeometry = *mut c_void;

    pub const RTC_GEOMETRY_TYPE_TRIANGLE: c_int = 0;
    pub const RTC_BUFFER_TYPE_INDEX: c_int = 0;
    pub const RTC_BUFFER_TYPE_VERTEX: c_int = 1;
    pub const RTC_FORMAT_UINT3: c_int = 0x5003;
    pub const RTC_FORMAT_FLOAT3: c_int = 0x9003;
    pub const RTC_BUILD_QUALITY_MEDIUM: c_int = 1;
    pub const RTC_BUILD_QUALITY_HIGH: c_int = 2;
    pub const RTC_INVALID_GEOMETRY_ID: c_uint = u32::MAX;
    pub const RTC_DEVICE_PROPERTY_VERSION: c_int = 0;
    pub const RTC_DEVICE_PROPERTY_TASKING_SYSTEM: c_int = 128;

    /// `struct RTCIntersectContext` with `RTC_MAX_INSTANCE_LEVEL_COUNT == 1` and
    /// `RTC_MIN_WIDTH == 0` (Debian's build).
    #[repr(C)]
    pub struct RTCIntersectContext {
        pub flags: c_int,
        pub filter: *const c_void,
        pub inst_id: [c_uint; 1],
    }

    #[repr(C, align(16))]
    #[derive(Clone, Copy, Default)]
    pub struct RTCRay {
        pub org: [f32; 3],
        pub tnear: f32,
        pub dir: [f32; 3],
        pub time: f32,
        pub tfar: f32,
        pub mask: c_uint,
        pub id: c_uint,
        pub flags: c_uint,
    }

    #[repr(C, align(16))]
    #[derive(Clone, Copy, Default)]
    pub struct RTCHit {
        pub ng: [f32; 3],
        pub u: f32,
        pub v: f32,
        pub prim_id: c_uint,
        pub geom_id: c_uint,
        pub inst_id: [c_uint; 1],
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct RTCRayHit {
        pub ray: RTCRay,
        pub hit: RTCHit,
    }

    /// `struct RTCRay8` (structure of arrays, 32-byte aligned).
    #[repr(C, align(32))]
    #[derive(Clone, Copy, Default)]
    pub struct RTCRay8 {
        pub org_x: [f32; 8],
        pub org_y: [f32; 8],
        pub org_z: [f32; 8],
        pub tnear: [f32; 8],
        pub dir_x: [f32; 8],
        pub dir_y: [f32; 8],
        pub dir_z: [f32; 8],
        pub time: [f32; 8],
        pub tfar: [f32; 8],
        pub mask: [c_uint; 8],
        pub id: [c_uint; 8],
        pub flags: [c_uint; 8],
    }

    #[repr(C, align(32))]
    #[derive(Clone, Copy, Default)]
    pub struct RTCHit8 {
        pub ng_x: [f32; 8],
        pub ng_y: [f32; 8],
        pub ng_z: [f32; 8],
        pub u: [f32; 8],
        pub v: [f32; 8],
        pub prim_id: [c_uint; 8],
        pub geom_id: [c_uint; 8],
        pub inst_id: [[c_uint; 8]; 1],
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct RTCRayHit8 {
        pub ray: RTCRay8,
        pub hit: RTCHit8,
    }

    #[link(name = "embree3")]
    extern "C" {
        pub fn rtcNewDevice(config: *const c_char) -> RTCDevice;
        pub fn rtcReleaseDevice(device: RTCDevice);
        pub fn rtcGetDeviceError(device: RTCDevice) -> c_int;
        pub fn rtcGetDeviceProperty(device: RTCDevice, prop: c_int) -> isize;
        pub fn rtcNewScene(device: RTCDevice) -> RTCScene;
        pub fn rtcReleaseScene(scene: RTCScene);
        pub fn rtcSetSceneBuildQuality(scene: RTCScene, quality: c_int);
        pub fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> c_uint;
        pub fn rtcCommitScene(scene: RTCScene);
        pub fn rtcNewGeometry(device: RTCDevice, ty: c_int) -> RTCGeometry;
        pub fn rtcSetNewGeometryBuffer(
            geometry: RTCGeometry,
            ty: c_int,
            slot: c_uint,
            format: c_int,
            byte_stride: usize,
            item_count: usize,
        ) -> *mut c_void;
        pub fn rtcCommitGeometry(geometry: RTCGeometry);
        pub fn rtcReleaseGeometry(geometry: RTCGeometry);
        pub fn rtcIntersect1(scene: RTCScene, context: *mut RTCIntersectContext, rayhit: *mut RTCRayHit);
        pub fn rtcOccluded1(scene: RTCScene, context: *mut RTCIntersectContext, ray: *mut RTCRay);
        pub fn rtcIntersect8(
            valid: *const c_int,
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            rayhit: *mut RTCRayHit8,
        );
        pub fn rtcOccluded8(valid: *const c_int, scene: RTCScene, context: *mut RTCIntersectContext, ray: *mut RTCRay8);
    }

    /// `rtcInitIntersectContext` (a `static inline` in the header).
    pub fn context() -> RTCIntersectContext {
        RTCIntersectContext { flags: 0, filter: std::ptr::null(), inst_id: [RTC_INVALID_GEOMETRY_ID] }
    }
}

/// A ray for [`EmbreeScene`]: same conventions as `radiosity::accel::Ray` (hits with
/// `tmin ≤ t ≤ tmax`; Embree's interval is closed where ours is open, which changes
/// nothing for rays that do not graze an end point).
#[derive(Clone, Copy, Debug)]
pub struct EmbreeRay {
    /// Origin.
    pub origin: Vec3,
    /// Direction (not normalised; t is in its units).
    pub dir: Vec3,
    /// Start of the segment.
    pub tmin: f32,
    /// End of the segment.
    pub tmax: f32,
}

/// A closest hit: ray parameter, barycentrics of v1 and v2, and input triangle index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmbreeHit {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric of v1.
    pub u: f32,
    /// Barycentric of v2.
    pub v: f32,
    /// Index of the triangle in the input.
    pub prim: u32,
}

/// Build quality of the Embree scene (`rtcSetSceneBuildQuality`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    /// Embree's default: binned SAH (plus its fast spatial-split pre-pass when enabled).
    Medium,
    /// SAH with spatial splits (slower build, fewer node visits).
    High,
}

/// The valid mask of an 8-ray packet, aligned as Embree requires.
#[repr(C, align(32))]
struct Valid8([c_int; 8]);

/// An Embree device and a committed scene over one triangle mesh.
pub struct EmbreeScene {
    device: ffi::RTCDevice,
    scene: ffi::RTCScene,
}

// Embree documents committed scenes as safe to trace from any number of threads.
unsafe impl Send for EmbreeScene {}
unsafe impl Sync for EmbreeScene {}

/// An error reported by Embree.
#[derive(Debug)]
pub struct EmbreeError(pub String);

impl std::fmt::Display for EmbreeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "embree: {}", self.0)
    }
}
impl std::error::Error for EmbreeError {}

impl EmbreeScene {
    /// Creates a device with Embree's configuration string `config` (e.g. `"threads=2"`,
    /// `"threads=1,isa=avx2,verbose=1"`) and builds a scene over `tris`.
    pub fn build(tris: &[[Vec3; 3]], config: &str, quality: Quality) -> Result<EmbreeScene, EmbreeError> {
        let config = CString::new(config).map_err(|_| EmbreeError("NUL in the configuration".into()))?;
        // SAFETY: every pointer passed is valid for the call; buffers returned by
        // rtcSetNewGeometryBuffer are written within the sizes we asked for.
        unsafe {
            let device = ffi::rtcNewDevice(config.as_ptr());
            if device.is_null() {
                return Err(EmbreeError("rtcNewDevice failed".into()));
            }
            let scene = ffi::rtcNewScene(device);
            let me = EmbreeScene { device, scene };
            ffi::rtcSetSceneBuildQuality(
                scene,
                match quality {
                    Quality::Medium => ffi::RTC_BUILD_QUALITY_MEDIUM,
                    Quality::High => ffi::RTC_BUILD_QUALITY_HIGH,
                },
            );
            if !tris.is_empty() {
                let geom = ffi::rtcNewGeometry(device, ffi::RTC_GEOMETRY_TYPE_TRIANGLE);
                let n = tris.len();
                let vb = ffi::rtcSetNewGeometryBuffer(geom, ffi::RTC_BUFFER_TYPE_VERTEX, 0, ffi::RTC_FORMAT_FLOAT3, 12, 3 * n)
                    as *mut [f32; 3];
                let ib = ffi::rtcSetNewGeometryBuffer(geom, ffi::RTC_BUFFER_TYPE_INDEX, 0, ffi::RTC_FORMAT_UINT3, 12, n)
                    as *mut [u32; 3];
                if vb.is_null() || ib.is_null() {
                    ffi::rtcReleaseGeometry(geom);
                    return Err(me.error("rtcSetNewGeometryBuffer"));
                }
                let verts = std::slice::from_raw_parts_mut(vb, 3 * n);
                let idx = std::slice::from_raw_parts_mut(ib, n);
                for (i, t) in tris.iter().enumerate() {
                    for k in 0..3 {
                        verts[3 * i + k] = t[k].to_array();
                    }
                    let b = 3 * i as u32;
                    idx[i] = [b, b + 1, b + 2];
                }
                ffi::rtcCommitGeometry(geom);
                ffi::rtcAttachGeometry(scene, geom);
                ffi::rtcReleaseGeometry(geom);
            }
            ffi::rtcCommitScene(scene);
            match ffi::rtcGetDeviceError(device) {
                0 => Ok(me),
                _ => Err(me.error("rtcCommitScene")),
            }
        }
    }

    fn error(&self, what: &str) -> EmbreeError {
        // SAFETY: the device is alive.
        let code = unsafe { ffi::rtcGetDeviceError(self.device) };
        EmbreeError(format!("{what} failed (RTCError {code})"))
    }

    /// Embree's version and tasking system, e.g. "3.13.5 (TBB)".
    pub fn describe(&self) -> String {
        // SAFETY: the device is alive.
        let (v, task) = unsafe {
            (
                ffi::rtcGetDeviceProperty(self.device, ffi::RTC_DEVICE_PROPERTY_VERSION),
                ffi::rtcGetDeviceProperty(self.device, ffi::RTC_DEVICE_PROPERTY_TASKING_SYSTEM),
            )
        };
        let task = match task {
            0 => "internal tasking",
            1 => "TBB",
            2 => "PPL",
            _ => "?",
        };
        format!("{}.{}.{} ({task})", v / 10000, (v / 100) % 100, v % 100)
    }

    /// Closest hit (`rtcIntersect1`).
    #[inline]
    pub fn intersect(&self, ray: &EmbreeRay) -> Option<EmbreeHit> {
        let mut rh = ffi::RTCRayHit {
            ray: ffi::RTCRay {
                org: ray.origin.to_array(),
                tnear: ray.tmin,
                dir: ray.dir.to_array(),
                time: 0.0,
                tfar: ray.tmax,
                mask: u32::MAX,
                id: 0,
                flags: 0,
            },
            hit: ffi::RTCHit { geom_id: ffi::RTC_INVALID_GEOMETRY_ID, ..Default::default() },
        };
        let mut ctx = ffi::context();
        // SAFETY: the scene is committed; `ctx` and `rh` live through the call.
        unsafe { ffi::rtcIntersect1(self.scene, &mut ctx, &mut rh) };
        (rh.hit.geom_id != ffi::RTC_INVALID_GEOMETRY_ID).then_some(EmbreeHit {
            t: rh.ray.tfar,
            u: rh.hit.u,
            v: rh.hit.v,
            prim: rh.hit.prim_id,
        })
    }

    /// Any hit (`rtcOccluded1`).
    #[inline]
    pub fn occluded(&self, ray: &EmbreeRay) -> bool {
        let mut r = ffi::RTCRay {
            org: ray.origin.to_array(),
            tnear: ray.tmin,
            dir: ray.dir.to_array(),
            time: 0.0,
            tfar: ray.tmax,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        };
        let mut ctx = ffi::context();
        // SAFETY: as above.
        unsafe { ffi::rtcOccluded1(self.scene, &mut ctx, &mut r) };
        r.tfar == f32::NEG_INFINITY
    }

    /// Closest hits of up to 8 rays as one packet (`rtcIntersect8`), written to `out`.
    pub fn intersect8(&self, rays: &[EmbreeRay], out: &mut [Option<EmbreeHit>]) {
        assert!(rays.len() <= 8 && out.len() >= rays.len());
        let mut valid = Valid8([0; 8]);
        let mut p = ffi::RTCRayHit8::default();
        for (i, r) in rays.iter().enumerate() {
            valid.0[i] = -1;
            p.ray.org_x[i] = r.origin.x;
            p.ray.org_y[i] = r.origin.y;
            p.ray.org_z[i] = r.origin.z;
            p.ray.dir_x[i] = r.dir.x;
            p.ray.dir_y[i] = r.dir.y;
            p.ray.dir_z[i] = r.dir.z;
            p.ray.tnear[i] = r.tmin;
            p.ray.tfar[i] = r.tmax;
            p.ray.mask[i] = u32::MAX;
            p.hit.geom_id[i] = ffi::RTC_INVALID_GEOMETRY_ID;
        }
        let mut ctx = ffi::context();
        // SAFETY: `valid` and `p` are 32-byte-aligned locals living through the call, as
        // rtcIntersect8 requires.
        unsafe { ffi::rtcIntersect8(valid.0.as_ptr(), self.scene, &mut ctx, &mut p) };
        for (i, o) in out[..rays.len()].iter_mut().enumerate() {
            *o = (p.hit.geom_id[i] != ffi::RTC_INVALID_GEOMETRY_ID).then_some(EmbreeHit {
                t: p.ray.tfar[i],
                u: p.hit.u[i],
                v: p.hit.v[i],
                prim: p.hit.prim_id[i],
            });
        }
    }

    /// Any-hit for up to 8 rays as one packet (`rtcOccluded8`), written to `out`.
    pub fn occluded8(&self, rays: &[EmbreeRay], out: &mut [bool]) {
        assert!(rays.len() <= 8 && out.len() >= rays.len());
        let mut valid = Valid8([0; 8]);
        let mut p = ffi::RTCRay8::default();
        for (i, r) in rays.iter().enumerate() {
            valid.0[i] = -1;
            p.org_x[i] = r.origin.x;
            p.org_y[i] = r.origin.y;
            p.org_z[i] = r.origin.z;
            p.dir_x[i] = r.dir.x;
            p.dir_y[i] = r.dir.y;
            p.dir_z[i] = r.dir.z;
            p.tnear[i] = r.tmin;
            p.tfar[i] = r.tmax;
            p.mask[i] = u32::MAX;
        }
        let mut ctx = ffi::context();
        // SAFETY: as in `intersect8`.
        unsafe { ffi::rtcOccluded8(valid.0.as_ptr(), self.scene, &mut ctx, &mut p) };
        for (o, tfar) in out[..rays.len()].iter_mut().zip(p.tfar) {
            *o = tfar == f32::NEG_INFINITY;
        }
    }
}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: created in `build`, released once.
        unsafe {
            ffi::rtcReleaseScene(self.scene);
            ffi::rtcReleaseDevice(self.device);
        }
    }
}
