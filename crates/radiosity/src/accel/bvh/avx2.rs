//! The traversal [`Kernel`] with x86-64 AVX2 intrinsics: eight child boxes in one 256-bit
//! slab test (Wald, Benthin & Boulos 2008; Dammertz, Hanika & Keller 2008), four triangles
//! in one 128-bit Möller–Trumbore test (Möller & Trumbore 1997, Embree's deferred-division
//! form, Wald et al. 2014) — the same arithmetic, in the same order, as the portable kernel
//! in `kernel.rs`, so both give identical hits.
//!
//! This is the only module of the library with `unsafe` code, for two reasons the safe
//! subset cannot express: loads and stores of SIMD registers take raw pointers, and a
//! function compiled with AVX2 enabled may only be entered once the CPU is known to have
//! it. Soundness rests on one invariant: an [`Avx2`] value exists only where
//! `is_x86_feature_detected!("avx2")` returned true ([`Avx2::detect`] is its only
//! constructor), and every `unsafe` block here is reached only through an `Avx2` value.
//! The pointers are to whole `[f32; 8]` / `[f32; 4]` arrays, read or written in full.
//!
//! The traversal loop itself (`traverse.rs`, safe code) is instantiated inside the
//! `#[target_feature(enable = "avx2")]` entry points below, so the compiler inlines the
//! kernel into it and emits VEX code throughout, with no per-node dispatch.
#![allow(unsafe_code)]

use std::arch::x86_64::*;

use super::kernel::{Kernel, RayPre};
use super::layout::{prow, NodeUnits, PacketUnits, PACKET, WIDTH};
use super::{traverse, Bvh, Hit, Ray};

/// Proof that the CPU has AVX2 (see the module docs).
#[derive(Clone, Copy, Debug)]
pub(super) struct Avx2(());

impl Avx2 {
    /// `Some` when the CPU has AVX2.
    pub fn detect() -> Option<Avx2> {
        is_x86_feature_detected!("avx2").then_some(Avx2(()))
    }
}

impl Kernel for Avx2 {
    #[inline(always)]
    fn boxes(self, node: &NodeUnits, ray: &RayPre, tmax: f32, dist: &mut [f32; WIDTH]) -> u32 {
        // SAFETY: `self` proves AVX2; each load reads one whole `[f32; 8]` unit of the node
        // and the store writes the whole `dist` array.
        unsafe {
            let row = |r: usize| _mm256_loadu_ps(node[r].0.as_ptr());
            let slab = |a: usize, r: usize, inv: f32| {
                _mm256_mul_ps(_mm256_sub_ps(row(r), _mm256_set1_ps(ray.org[a])), _mm256_set1_ps(inv))
            };
            // Each slab distance is the first operand: a NaN one (0·∞) is dropped.
            let tn = _mm256_max_ps(
                slab(2, ray.near[2], ray.inv[2]),
                _mm256_max_ps(
                    slab(1, ray.near[1], ray.inv[1]),
                    _mm256_max_ps(slab(0, ray.near[0], ray.inv[0]), _mm256_set1_ps(ray.tmin)),
                ),
            );
            let tf = _mm256_min_ps(
                slab(2, ray.far[2], ray.inv_far[2]),
                _mm256_min_ps(
                    slab(1, ray.far[1], ray.inv_far[1]),
                    _mm256_min_ps(slab(0, ray.far[0], ray.inv_far[0]), _mm256_set1_ps(tmax)),
                ),
            );
            _mm256_storeu_ps(dist.as_mut_ptr(), tn);
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32
        }
    }

    #[inline(always)]
    fn triangles(self, p: &PacketUnits, ray: &RayPre, tmax: f32, t: &mut [f32; PACKET]) -> u32 {
        // SAFETY: `self` proves AVX2; each load reads one whole `[f32; 4]` row of the
        // packet and the store writes the whole `t` array.
        unsafe {
            let ld = |a: &[f32; PACKET]| _mm_loadu_ps(a.as_ptr());
            let [dx, dy, dz] = ray.dir.map(|d| _mm_set1_ps(d));
            let cx = _mm_sub_ps(ld(prow(p, 0)), _mm_set1_ps(ray.org[0]));
            let cy = _mm_sub_ps(ld(prow(p, 1)), _mm_set1_ps(ray.org[1]));
            let cz = _mm_sub_ps(ld(prow(p, 2)), _mm_set1_ps(ray.org[2]));
            let rx = _mm_sub_ps(_mm_mul_ps(cy, dz), _mm_mul_ps(cz, dy));
            let ry = _mm_sub_ps(_mm_mul_ps(cz, dx), _mm_mul_ps(cx, dz));
            let rz = _mm_sub_ps(_mm_mul_ps(cx, dy), _mm_mul_ps(cy, dx));
            let dot = |x: __m128, y: __m128, z: __m128, a: [__m128; 3]| {
                _mm_add_ps(_mm_add_ps(_mm_mul_ps(x, a[0]), _mm_mul_ps(y, a[1])), _mm_mul_ps(z, a[2]))
            };
            let e1 = [ld(prow(p, 3)), ld(prow(p, 4)), ld(prow(p, 5))];
            let e2 = [ld(prow(p, 6)), ld(prow(p, 7)), ld(prow(p, 8))];
            let ng = [
                _mm_sub_ps(_mm_mul_ps(e1[1], e2[2]), _mm_mul_ps(e1[2], e2[1])),
                _mm_sub_ps(_mm_mul_ps(e1[2], e2[0]), _mm_mul_ps(e1[0], e2[2])),
                _mm_sub_ps(_mm_mul_ps(e1[0], e2[1]), _mm_mul_ps(e1[1], e2[0])),
            ];
            let den = dot(dx, dy, dz, ng);
            let sign_bit = _mm_set1_ps(-0.0);
            let sgn = _mm_and_ps(den, sign_bit);
            let abs_den = _mm_xor_ps(den, sgn);
            let u = _mm_xor_ps(dot(rx, ry, rz, e2), sgn);
            let v = _mm_xor_ps(_mm_xor_ps(dot(rx, ry, rz, e1), sign_bit), sgn);
            let zero = _mm_setzero_ps();
            let inside = _mm_and_ps(
                _mm_and_ps(_mm_cmp_ps::<_CMP_NEQ_OQ>(den, zero), _mm_cmp_ps::<_CMP_GE_OQ>(u, zero)),
                _mm_and_ps(_mm_cmp_ps::<_CMP_GE_OQ>(v, zero), _mm_cmp_ps::<_CMP_LE_OQ>(_mm_add_ps(u, v), abs_den)),
            );
            if _mm_movemask_ps(inside) == 0 {
                return 0;
            }
            let tt = _mm_div_ps(_mm_xor_ps(dot(cx, cy, cz, ng), sgn), abs_den);
            let ok = _mm_and_ps(
                inside,
                _mm_and_ps(
                    _mm_cmp_ps::<_CMP_GT_OQ>(tt, _mm_set1_ps(ray.tmin)),
                    _mm_cmp_ps::<_CMP_LT_OQ>(tt, _mm_set1_ps(tmax)),
                ),
            );
            _mm_storeu_ps(t.as_mut_ptr(), tt);
            _mm_movemask_ps(ok) as u32
        }
    }

    #[inline(always)]
    fn prefetch<T>(self, x: &T) {
        let p = x as *const T as *const i8;
        for line in 0..std::mem::size_of::<T>().div_ceil(64) {
            // SAFETY: a prefetch never faults; the address is within (or one line past the
            // start of) `x`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * line)) };
        }
    }
}

// `unsafe fn` rather than a safe `#[target_feature]` fn (Rust ≥ 1.86) to keep the
// workspace's rust-version 1.85; the callers below uphold the same contract.
#[target_feature(enable = "avx2")]
unsafe fn closest_avx2(k: Avx2, bvh: &Bvh, ray: &Ray, skip: impl Fn(u32) -> bool) -> Option<Hit> {
    traverse::closest(k, bvh, ray, skip)
}

#[target_feature(enable = "avx2")]
unsafe fn occluded_avx2(k: Avx2, bvh: &Bvh, ray: &Ray, skip: impl Fn(u32) -> bool) -> bool {
    traverse::occluded(k, bvh, ray, skip)
}

/// Closest hit with the AVX2 kernel.
#[inline]
pub(super) fn closest(k: Avx2, bvh: &Bvh, ray: &Ray, skip: impl Fn(u32) -> bool) -> Option<Hit> {
    // SAFETY: `k` proves the CPU has AVX2.
    unsafe { closest_avx2(k, bvh, ray, skip) }
}

/// Any hit with the AVX2 kernel.
#[inline]
pub(super) fn occluded(k: Avx2, bvh: &Bvh, ray: &Ray, skip: impl Fn(u32) -> bool) -> bool {
    // SAFETY: `k` proves the CPU has AVX2.
    unsafe { occluded_avx2(k, bvh, ray, skip) }
}
