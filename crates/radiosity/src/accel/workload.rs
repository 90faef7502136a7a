//! Incoherent ray workloads for measuring ray casting (`radiosity bench rays`): fixed,
//! seeded sets from area-weighted uniform points on a scene's triangles, so that our BVH
//! and another tracer (Embree) can be timed on the very same rays.
//!
//! - closest-hit rays leaving a surface point in a cosine-weighted direction about its
//!   normal (what gathering casts);
//! - segments between two random surface points, traced as any-hit queries (form-factor
//!   visibility, as [`super::SceneRays::visible`] casts them), with the polygons of their
//!   end points.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::Ray;
use crate::sampling::{basis, cosine_hemisphere, mix64, unit_f64};
use crate::scene::Scene;

/// Fan triangulation of the polygons, as `SceneRays::new` does it, with each triangle's polygon.
pub fn triangles(scene: &Scene) -> (Vec<[Vec3; 3]>, Vec<u32>) {
    let mut tris = Vec::new();
    let mut poly = Vec::new();
    for (pi, p) in scene.polygons.iter().enumerate() {
        let v = &p.vertices;
        for i in 1..v.len().saturating_sub(1) {
            tris.push([v[0].as_vec3(), v[i].as_vec3(), v[i + 1].as_vec3()]);
            poly.push(pi as u32);
        }
    }
    (tris, poly)
}

/// The two ray sets of one scene.
pub struct RaySet {
    /// From a surface point, cosine-weighted about the normal, unit direction, t ∈ (ε, ∞).
    pub closest: Vec<Ray>,
    /// Between two surface points: direction b − a, t ∈ (SEGMENT_EPS, 1 − SEGMENT_EPS).
    pub segments: Vec<Ray>,
    /// The polygons of the segments' end points.
    pub segment_polys: Vec<(u32, u32)>,
}

/// `n` rays of each kind on the triangles `tris` (of polygons `tri_poly`, as [`triangles`]
/// gives them) from `seed`; closest-hit rays start `1e-5 · diag` off their surface.
pub fn make_rays(tris: &[[Vec3; 3]], tri_poly: &[u32], n: usize, seed: u64, diag: f64) -> RaySet {
    let mut cdf = Vec::with_capacity(tris.len());
    let mut total = 0.0f64;
    for t in tris {
        let [a, b, c] = t.map(|p| p.as_dvec3());
        total += 0.5 * (b - a).cross(c - a).length();
        cdf.push(total);
    }
    let u = |i: u64, k: u64| unit_f64(mix64(seed ^ mix64(i.wrapping_mul(8).wrapping_add(k))));
    // An area-weighted uniform point: (point, triangle).
    let point = |i: u64, k: u64| -> (DVec3, usize) {
        let x = u(i, k) * total;
        let ti = cdf.partition_point(|&c| c <= x).min(tris.len() - 1);
        let [a, b, c] = tris[ti].map(|p| p.as_dvec3());
        let (s, r) = (u(i, k + 1).sqrt(), u(i, k + 2));
        (a * (1.0 - s) + b * (s * (1.0 - r)) + c * (s * r), ti)
    };
    let eps = (1e-5 * diag) as f32;
    let closest = (0..n as u64)
        .into_par_iter()
        .map(|i| {
            let (p, ti) = point(i, 0);
            let [a, b, c] = tris[ti].map(|p| p.as_dvec3());
            let nrm = (b - a).cross(c - a).normalize_or(DVec3::Z);
            let (t, bt) = basis(nrm);
            let d = cosine_hemisphere(u(i, 3), u(i, 4));
            let dir = (t * d.x + bt * d.y + nrm * d.z).normalize();
            Ray::new(p.as_vec3(), dir.as_vec3(), eps, f32::INFINITY)
        })
        .collect();
    let (segments, segment_polys) = (0..n as u64)
        .into_par_iter()
        .map(|i| {
            let (p, ta) = point(n as u64 + i, 0);
            let (q, tb) = point(n as u64 + i, 3);
            let eps = super::SEGMENT_EPS;
            (Ray::new(p.as_vec3(), (q - p).as_vec3(), eps, 1.0 - eps), (tri_poly[ta], tri_poly[tb]))
        })
        .unzip();
    RaySet { closest, segments, segment_polys }
}
