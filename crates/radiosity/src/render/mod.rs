//! Stage 7: rendering — the solved scene seen through a pinhole camera.
//!
//! Images hold linear radiance `L = B/π` per pixel (diffuse surfaces), averaged over the
//! pixel's footprint (box filter, `spp × spp` stratified samples); back faces of one-sided
//! surfaces and empty background are black. Tone mapping is left to [`crate::output`].
//!
//! - [`gouraud`]: radiosity interpolated from the vertices (bilinear on quads,
//!   barycentric on triangles), or flat per element — the instant preview.
//! - [`gather`]: final gather — direct light exact per pixel, indirect light from the
//!   solution — for images that match a path tracer.

pub mod camera;
pub mod gather;
pub mod gouraud;
pub mod lightmap;
pub mod raster;

pub use camera::PinholeCamera;

use crate::Rgb;

/// A linear-radiance image; pixel (0,0) is top-left, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Radiance per pixel, row-major.
    pub pixels: Vec<Rgb>,
}

impl Image {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Image { width, height, pixels: vec![Rgb::ZERO; width * height] }
    }
    /// Pixel at column x, row y.
    pub fn at(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }
}

/// Bytes of the buffers one view's renderer allocates for a `width × height` image with
/// `spp_axis²` samples per pixel: the radiance image (3 × f64 per pixel) and, for the final
/// gather (`gather == true`), its per-pixel sums and the adaptive sampling's three maps
/// ([`gather::PIXEL_STATE_BYTES`]), or for the Gouraud/flat renderer its supersampled
/// z-buffer of element ids and parameters (4 + 8 bytes per sample). Saturating, so absurd
/// sizes compare as huge.
pub fn image_memory_bytes(width: usize, height: usize, spp_axis: usize, gather: bool) -> u64 {
    let pixels = (width as u64).saturating_mul(height as u64);
    let image = pixels.saturating_mul(std::mem::size_of::<Rgb>() as u64);
    if gather {
        image.saturating_add(pixels.saturating_mul(gather::PIXEL_STATE_BYTES))
    } else {
        let s = spp_axis.max(1) as u64;
        image.saturating_add(pixels.saturating_mul(s * s).saturating_mul(12))
    }
}

/// What a view's primary rays hit, on a coarse grid of rays through the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ViewCoverage {
    /// Rays that hit the front of a surface (what the image shows).
    pub front: usize,
    /// Rays that hit the back of a one-sided surface (drawn black).
    pub back: usize,
    /// Rays that hit nothing (background, black).
    pub background: usize,
}

impl ViewCoverage {
    /// Rays cast.
    pub fn total(&self) -> usize {
        self.front + self.back + self.background
    }

    /// Why the image is (nearly) black, if it is: fewer than 1 % of the rays reach the
    /// front of a surface; then it sees back faces (at least 1 % of the rays meet one) or
    /// nothing. The text completes "the camera …".
    pub fn problem(&self) -> Option<String> {
        let n = self.total().max(1);
        if self.front * 100 >= n {
            return None;
        }
        Some(if self.back * 100 >= n {
            format!(
                "sees only back faces of one-sided surfaces ({:.0} % of the image): the image is black; use --two-sided or move the camera inside",
                100.0 * self.back as f64 / n as f64
            )
        } else {
            "sees no surface: the image is black (is it looking away from the scene?)".to_string()
        })
    }
}

/// Casts `n × n` rays through the image of `camera` (pixel centres of an `n × n` image of
/// the same aspect as `width × height`) against the scene's polygons and counts what they
/// hit first — the renderers' visibility (the back of one side of a two-sided pair shows
/// its twin) and front test, without a mesh or a solution, so it can run before solving.
pub fn view_coverage(
    scene: &crate::scene::Scene,
    rays: &crate::accel::SceneRays,
    camera: &crate::scene::Camera,
    width: usize,
    height: usize,
    n: usize,
) -> ViewCoverage {
    let mut c = ViewCoverage::default();
    for (eye, dir) in probes(camera, width, height, n) {
        match rays.closest_facing(eye.as_vec3(), dir.as_vec3(), f32::INFINITY, None) {
            None => c.background += 1,
            Some((_, p)) => {
                let poly = &scene.polygons[p as usize];
                if !poly.two_sided && poly.normal.dot(dir) >= 0.0 {
                    c.back += 1;
                } else {
                    c.front += 1;
                }
            }
        }
    }
    c
}

/// The eye and the directions through the pixel centres of an `n × n` image of the same
/// aspect as `width × height`: the probes of [`view_coverage`] and [`lit_coverage`].
fn probes(camera: &crate::scene::Camera, width: usize, height: usize, n: usize) -> impl Iterator<Item = (glam::DVec3, glam::DVec3)> {
    let (w, h) = (width.max(1) as f64, height.max(1) as f64);
    let cam = PinholeCamera::new(camera, width.max(1), height.max(1));
    let n = n.max(1);
    (0..n * n).map(move |k| {
        let (i, j) = (k % n, k / n);
        let x = (i as f64 + 0.5) / n as f64 * w;
        let y = (j as f64 + 0.5) / n as f64 * h;
        (cam.eye, cam.direction(x, y))
    })
}

/// After a solve: of `n × n` rays through the image of `camera` (as [`view_coverage`]),
/// how many meet an element whose radiosity (luminance) is above 1e-3 of the area-weighted
/// mean — a *lit* surface — and how many were cast. A camera outside a closed two-sided
/// room sees only fronts, all unlit: [`view_coverage`] finds nothing wrong, the image is
/// black all the same.
pub fn lit_coverage(
    mesh: &crate::mesh::Mesh,
    tracer: &gouraud::ElementTracer,
    radiosity: &[Rgb],
    camera: &crate::scene::Camera,
    width: usize,
    height: usize,
    n: usize,
) -> (usize, usize) {
    let (mut sum, mut area) = (0.0, 0.0);
    for (e, b) in mesh.elements.iter().zip(radiosity) {
        sum += e.area * crate::luminance(*b);
        area += e.area;
    }
    let threshold = 1e-3 * sum / area.max(f64::MIN_POSITIVE);
    let lit = probes(camera, width, height, n)
        .filter(|&(eye, dir)| {
            tracer.trace(eye, dir).is_some_and(|(e, _)| {
                mesh.elements[e as usize].normal.dot(dir) < 0.0
                    && radiosity.get(e as usize).is_some_and(|b| crate::luminance(*b) > threshold)
            })
        })
        .count();
    (lit, n.max(1) * n.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;
    use glam::DVec3;

    #[test]
    fn view_coverage_tells_back_faces_from_background() {
        let scene = crate::scene::Scene::from_desc(crate::scene::builtin::furnace(0.5, 1.0)).unwrap();
        let rays = crate::accel::SceneRays::new(&scene.polygons);
        let cov = |cam: &Camera| view_coverage(&scene, &rays, cam, 64, 48, 32);
        let inside = cov(&scene.camera.unwrap());
        assert_eq!((inside.front, inside.problem()), (32 * 32, None));
        // Outside the closed box, looking at it: only the backs of the inward walls.
        let outside = Camera { position: DVec3::new(0.5, 0.5, -2.0), look_at: DVec3::splat(0.5), up: DVec3::Y, vfov_deg: 45.0 };
        let c = cov(&outside);
        assert_eq!(c.front, 0);
        let why = c.problem().unwrap();
        assert!(why.contains("only back faces") && why.contains("--two-sided"), "{why}");
        // Looking away: nothing at all.
        let away = Camera { look_at: DVec3::new(0.5, 0.5, -3.0), ..outside };
        let c = cov(&away);
        assert_eq!(c.background, 32 * 32);
        assert!(c.problem().unwrap().contains("sees no surface"));
    }

    #[test]
    fn image_memory_counts_every_buffer() {
        assert_eq!(image_memory_bytes(100, 10, 6, true), 24_000 + 1000 * gather::PIXEL_STATE_BYTES);
        assert_eq!(image_memory_bytes(100, 10, 3, false), 24_000 + 9 * 12_000);
        assert!(image_memory_bytes(65535, 65535, 64, false) > 1 << 40);
    }
}
