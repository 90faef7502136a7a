//! The two data-parallel steps of traversal — one ray against the eight boxes of a node, one
//! ray against a packet of four triangles — behind a [`Kernel`] trait, with the portable
//! implementation every target can run. `avx2.rs` implements the same arithmetic with
//! `std::arch` intrinsics; both give bit-identical results (no fused multiply-adds, the same
//! operation order), which the tests rely on.
//!
//! Box test: the slab method (Kay & Kajiya 1986) with the near and far planes of each axis
//! picked once per ray from the sign of the direction, so an inverted empty slot can never
//! pass, and the far distance scaled by 1 + 2γ₃ so rounding can never cull a box the ray
//! does meet (Ize 2013, "Robust BVH ray traversal"). A plane the ray runs within gives
//! NaN (0·∞); the `max`/`min` operand order drops it, which treats the slab as entered.
//!
//! Triangle test: Möller & Trumbore (1997) in the form Embree uses (Wald et al. 2014), with
//! the geometric normal precomputed: with C = v0 − o, R = C × d, den = n·d the barycentrics
//! are u = R·e2 / den, v = −R·e1 / den and t = C·n / den. The edge tests run on the
//! undivided values with den's sign folded in; the division happens only for packets that
//! pass them. Edges count as inside (u, v ≥ 0, u + v ≤ 1); rays parallel to the plane
//! (den = 0) and NaN inputs never hit.

use super::layout::{Node, TriPacket, PACKET, WIDTH};
use super::Ray;

/// 1 + 2γ₃ with γₙ = nε/(1 − nε), ε = 2⁻²⁴ (Pharr, Jakob & Humphreys, PBR 3rd ed. §3.9).
pub(super) const FAR_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// A ray prepared for traversal.
#[derive(Clone, Copy, Debug)]
pub(super) struct RayPre {
    pub org: [f32; 3],
    pub dir: [f32; 3],
    /// 1/dir per axis (±∞ for a zero component).
    pub inv: [f32; 3],
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
        // The sign of 1/d (not of d) so that d = −0 gives −∞ with the planes swapped.
        let near = [0, 1, 2].map(|a| 2 * a + inv[a].is_sign_negative() as usize);
        RayPre {
            org: ray.origin.to_array(),
            dir: ray.dir.to_array(),
            inv,
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
    fn boxes(self, node: &Node, ray: &RayPre, tmax: f32, dist: &mut [f32; WIDTH]) -> u32;

    /// Bit `l` set when triangle `l` is hit at `tmin < t < tmax`; `t[l]` is then the hit
    /// distance.
    fn triangles(self, p: &TriPacket, ray: &RayPre, tmax: f32, t: &mut [f32; PACKET]) -> u32;
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
fn lane_values(p: &TriPacket, ray: &RayPre, l: usize) -> (f32, f32, f32, f32, f32) {
    let [dx, dy, dz] = ray.dir;
    let cx = p.v0[0][l] - ray.org[0];
    let cy = p.v0[1][l] - ray.org[1];
    let cz = p.v0[2][l] - ray.org[2];
    let rx = cy * dz - cz * dy;
    let ry = cz * dx - cx * dz;
    let rz = cx * dy - cy * dx;
    let den = p.ng[0][l] * dx + p.ng[1][l] * dy + p.ng[2][l] * dz;
    let abs_den = xorsign(den, den);
    let u = xorsign(rx * p.e2[0][l] + ry * p.e2[1][l] + rz * p.e2[2][l], den);
    let v = xorsign(-(rx * p.e1[0][l] + ry * p.e1[1][l] + rz * p.e1[2][l]), den);
    let t = xorsign(cx * p.ng[0][l] + cy * p.ng[1][l] + cz * p.ng[2][l], den);
    (den, abs_den, u, v, t)
}

/// Barycentrics (of v1, v2) of lane `l`, for a lane a kernel reported hit.
#[inline]
pub(super) fn lane_uv(p: &TriPacket, ray: &RayPre, l: usize) -> (f32, f32) {
    let (_, abs_den, u, v, _) = lane_values(p, ray, l);
    (u / abs_den, v / abs_den)
}

/// Plain Rust, one lane at a time; the reference the SIMD kernel must match bit for bit.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Portable;

impl Kernel for Portable {
    #[inline(always)]
    fn boxes(self, node: &Node, ray: &RayPre, tmax: f32, dist: &mut [f32; WIDTH]) -> u32 {
        let mut mask = 0;
        for i in 0..WIDTH {
            let slab = |a: usize, row: usize| (node.bounds[row][i] - ray.org[a]) * ray.inv[a];
            let tn = max_ps(slab(2, ray.near[2]), max_ps(slab(1, ray.near[1]), max_ps(slab(0, ray.near[0]), ray.tmin)));
            let tf = min_ps(slab(2, ray.far[2]), min_ps(slab(1, ray.far[1]), min_ps(slab(0, ray.far[0]), f32::INFINITY)));
            let tf = min_ps(tf * FAR_SCALE, tmax);
            dist[i] = tn;
            mask |= ((tn <= tf) as u32) << i;
        }
        mask
    }

    #[inline(always)]
    fn triangles(self, p: &TriPacket, ray: &RayPre, tmax: f32, t: &mut [f32; PACKET]) -> u32 {
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
