//! The two data-parallel steps of traversal — one ray against the eight boxes of a node, one
//! ray against a packet of four triangles — behind a [`Kernel`] trait, with the portable
//! implementation every target can run. `avx2.rs` implements the same arithmetic with
//! `std::arch` intrinsics; both give bit-identical results (no fused multiply-adds, the same
//! operation order), which the tests rely on.
//!
//! Box test: the slab method (Kay & Kajiya 1986) with the near and far planes of each axis
//! picked once per ray from the sign of 1/d, so an inverted empty slot can never pass, and
//! far distances scaled up by 1 + 4γ₃ so rounding can never cull a box the ray does meet
//! (Ize 2013, "Robust BVH ray traversal"). Distances are (plane − origin) · (1/d), not the
//! fused plane · (1/d) − origin · (1/d): the latter saves six operations per node but
//! loses all precision near the origin of rays that start far from the world origin. A zero
//! direction component gives 1/d = ±∞ and, for a ray lying exactly in a box face (a
//! segment between two points of a flat floor), NaN = 0 · ∞: each slab distance enters
//! `max`/`min` as the first operand, which x86's `maxps`/`minps` (and [`max_ps`] /
//! [`min_ps`]) drop in favour of the second, so such a slab counts as entered — exactly
//! right for a ray in the face's plane. (Clamping |d| away from zero, as Embree does,
//! would cull those boxes, so that whether a segment grazing an edge in that plane is
//! blocked would depend on the tree.)
//!
//! Triangle test: Möller & Trumbore (1997) in the form Embree uses (Wald et al. 2014): with
//! n = e1 × e2, C = v0 − o, R = C × d, den = n·d the barycentrics
//! are u = R·e2 / den, v = −R·e1 / den and t = C·n / den. The edge tests run on the
//! undivided values with den's sign folded in; the division happens only for packets that
//! pass them. Edges count as inside (u, v ≥ 0, u + v ≤ 1); rays parallel to the plane
//! (den = 0) and NaN inputs never hit.

// The portable kernel's loops run over SIMD lanes and index several arrays by lane, as the
// intrinsics do; iterator chains would hide that correspondence.
#![allow(clippy::needless_range_loop)]

use super::layout::{prow, NodeUnits, PacketUnits, PACKET, WIDTH};
use super::Ray;

/// 1 + 4γ₃ with γₙ = nε/(1 − nε), ε = 2⁻²⁴ (Pharr, Jakob & Humphreys, PBR 3rd ed. §3.9):
/// far distances scaled by it exceed near distances whenever the exact ones do, covering
/// the rounding of 1/d, of (1/d)·FAR_SCALE, of the subtraction and of the product.
pub(super) const FAR_SCALE: f32 = 1.0 + 4.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);


/// A ray prepared for traversal.
#[derive(Clone, Copy, Debug)]
pub(super) struct RayPre {
    pub org: [f32; 3],
    pub dir: [f32; 3],
    /// 1/dir per axis (±∞ for a zero component).
    pub inv: [f32; 3],
    /// `inv · FAR_SCALE`: far-plane distances come out rounded up.
    pub inv_far: [f32; 3],
    /// Row of [`Node::bounds`] holding each axis's near plane (lower for a positive
    /// direction), and the far plane's row.
    pub near: [usize; 3],
    pub far: [usize; 3],
    pub tmin: f32,
}

impl RayPre {
    #[inline(always)]
    pub fn new(ray: &Ray) -> RayPre {
        let inv = ray.dir.recip().to_array();
        // The sign of 1/d, not of d, so that d = −0 gives −∞ with the planes swapped.
        let near = [0, 1, 2].map(|a| 2 * a + inv[a].is_sign_negative() as usize);
        RayPre {
            org: ray.origin.to_array(),
            dir: ray.dir.to_array(),
            inv,
            inv_far: inv.map(|i| i * FAR_SCALE),
            near,
            far: near.map(|n| n ^ 1),
            tmin: ray.tmin,
        }
    }
}

/// The data-parallel steps of traversal.
pub(super) trait Kernel: Copy {
    /// Bit `i` set when the ray meets child `i`'s box within `[tmin, tmax]`; `dist[i]` is
    /// then the entry distance.
    fn boxes(self, node: &NodeUnits, ray: &RayPre, tmax: f32, dist: &mut [f32; WIDTH]) -> u32;

    /// Bit `l` set when triangle `l` is hit at `tmin < t < tmax`; `t[l]` is then the hit
    /// distance.
    fn triangles(self, p: &PacketUnits, ray: &RayPre, tmax: f32, t: &mut [f32; PACKET]) -> u32;

    /// Starts loading `x` into the cache (a hint; may do nothing).
    #[inline(always)]
    fn prefetch<T>(self, _x: &T) {}
}

/// `a > b ? a : b` — `maxps`'s semantics: a NaN `a` yields `b`.
#[inline(always)]
pub(super) fn max_ps(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// `a < b ? a : b` — `minps`'s semantics: a NaN `a` yields `b`.
#[inline(always)]
pub(super) fn min_ps(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `x` with its sign flipped where `s` is negative.
#[inline(always)]
fn xorsign(x: f32, s: f32) -> f32 {
    f32::from_bits(x.to_bits() ^ (s.to_bits() & 0x8000_0000))
}

/// Undivided Möller–Trumbore values of lane `l`: (den, |den|, U, V, T) with den's sign
/// folded into U, V, T.
#[inline(always)]
fn lane_values(p: &PacketUnits, ray: &RayPre, l: usize) -> (f32, f32, f32, f32, f32) {
    let [dx, dy, dz] = ray.dir;
    let cx = prow(p, 0)[l] - ray.org[0];
    let cy = prow(p, 1)[l] - ray.org[1];
    let cz = prow(p, 2)[l] - ray.org[2];
    let rx = cy * dz - cz * dy;
    let ry = cz * dx - cx * dz;
    let rz = cx * dy - cy * dx;
    let e1 = [3, 4, 5].map(|k| prow(p, k)[l]);
    let e2 = [6, 7, 8].map(|k| prow(p, k)[l]);
    let nx = e1[1] * e2[2] - e1[2] * e2[1];
    let ny = e1[2] * e2[0] - e1[0] * e2[2];
    let nz = e1[0] * e2[1] - e1[1] * e2[0];
    let den = nx * dx + ny * dy + nz * dz;
    let abs_den = xorsign(den, den);
    let u = xorsign(rx * e2[0] + ry * e2[1] + rz * e2[2], den);
    let v = xorsign(-(rx * e1[0] + ry * e1[1] + rz * e1[2]), den);
    let t = xorsign(cx * nx + cy * ny + cz * nz, den);
    (den, abs_den, u, v, t)
}

/// Barycentrics (of v1, v2) of lane `l`, for a lane a kernel reported hit.
#[inline]
pub(super) fn lane_uv(p: &PacketUnits, ray: &RayPre, l: usize) -> (f32, f32) {
    let (_, abs_den, u, v, _) = lane_values(p, ray, l);
    (u / abs_den, v / abs_den)
}

/// Plain Rust, one lane at a time; the reference the SIMD kernel must match bit for bit.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Portable;

impl Kernel for Portable {
    #[inline(always)]
    fn boxes(self, node: &NodeUnits, ray: &RayPre, tmax: f32, dist: &mut [f32; WIDTH]) -> u32 {
        let mut mask = 0;
        for i in 0..WIDTH {
            let slab = |a: usize, row: usize, inv: f32| (node[row].0[i] - ray.org[a]) * inv;
            let tn = max_ps(slab(2, ray.near[2], ray.inv[2]), max_ps(slab(1, ray.near[1], ray.inv[1]), max_ps(slab(0, ray.near[0], ray.inv[0]), ray.tmin)));
            let tf = min_ps(slab(2, ray.far[2], ray.inv_far[2]), min_ps(slab(1, ray.far[1], ray.inv_far[1]), min_ps(slab(0, ray.far[0], ray.inv_far[0]), tmax)));
            dist[i] = tn;
            mask |= ((tn <= tf) as u32) << i;
        }
        mask
    }

    #[inline(always)]
    fn triangles(self, p: &PacketUnits, ray: &RayPre, tmax: f32, t: &mut [f32; PACKET]) -> u32 {
        let mut mask = 0;
        for l in 0..PACKET {
            let (den, abs_den, u, v, tt) = lane_values(p, ray, l);
            if den != 0.0 && u >= 0.0 && v >= 0.0 && u + v <= abs_den {
                let tl = tt / abs_den;
                if tl > ray.tmin && tl < tmax {
                    t[l] = tl;
                    mask |= 1 << l;
                }
            }
        }
        mask
    }
}
