//! Direct light from emitting polygons at a surface point, exact up to visibility:
//!
//! ```text
//! H_direct(x) = Σ_emitters π·L_e,Q · F(dA_x → Q) · V̂(x, Q)
//! ```
//!
//! with `F(dA_x → Q)` the contour integral ([`crate::form_factor::analytic::point_factor`]) and `V̂` the fraction
//! of stratified shadow rays that reach the emitter (many emitters: rays picked in
//! proportion to each one's unoccluded contribution, a cheap guide to it away from the
//! emitter, and the contour integral taken only for the emitters picked). Used by the final gather
//! ([`crate::render::gather`]) per pixel and by a-priori mesh refinement
//! ([`crate::mesh::adaptive`]) per element, so it lives below both.

use glam::DVec3;

use crate::accel::SceneRays;
use crate::geom::kernel::point_to_polygon;
use crate::scene::Scene;
use crate::Rgb;

/// An emitting polygon.
#[derive(Clone, Debug)]
pub struct Emitter {
    /// Scene polygon index.
    pub polygon: u32,
    /// Emitted exitance E = π·L_e (with an emission texture: its mean).
    pub exitance: Rgb,
    /// True if an emission texture varies its exitance: shadow rays then weigh each point
    /// by its own exitance.
    pub textured: bool,
    /// Cumulative fan-triangle areas (for uniform sampling).
    cdf: Vec<f64>,
    /// Area centroid, unit normal, area and the largest distance of a vertex from the
    /// centroid: what [`guide`] reads.
    centroid: DVec3,
    normal: DVec3,
    area: f64,
    radius: f64,
}

impl Emitter {
    /// Emitted exitance at point `y` of the emitter.
    #[inline]
    pub fn exitance_at(&self, scene: &Scene, y: DVec3) -> Rgb {
        if self.textured {
            scene.emission_at(self.polygon as usize, y, 0.0) * std::f64::consts::PI
        } else {
            self.exitance
        }
    }
}

/// The emitting polygons of a scene.
pub fn emitters(scene: &Scene) -> Vec<Emitter> {
    scene
        .polygons
        .iter()
        .enumerate()
        .filter_map(|(i, p)| {
            let m = &scene.materials[p.material as usize];
            if !m.is_emitter() {
                return None;
            }
            let v = &p.vertices;
            let mut cdf = Vec::with_capacity(v.len() - 2);
            let mut acc = 0.0;
            let mut moment = DVec3::ZERO;
            for k in 1..v.len() - 1 {
                let a = 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length();
                acc += a;
                moment += a * (v[0] + v[k] + v[k + 1]) / 3.0;
                cdf.push(acc);
            }
            let centroid = if acc > 0.0 { moment / acc } else { v[0] };
            let radius = v.iter().map(|p| (*p - centroid).length()).fold(0.0, f64::max);
            Some(Emitter {
                polygon: i as u32,
                exitance: m.exitance(),
                textured: m.emission_texture.is_some(),
                cdf,
                centroid,
                normal: p.normal,
                area: acc,
                radius,
            })
        })
        .collect()
}

/// Distance, in emitter radii, below which [`direct_irradiance_sampled`] weighs an emitter
/// by its exact factor instead of [`guide`]: beyond it the point-to-point factor is within
/// about (1/3)² = 11 % of the exact one.
const NEAR_RADII: f64 = 3.0;

/// A cheap stand-in for `F(dA_x → Q)` that picks the emitters shadow rays go to: the
/// point-to-point factor from the emitter's centroid, with the height over x's tangent
/// plane raised by the emitter's radius and the whole clamped to 1. It is nonzero wherever
/// the contour integral is (x in front of the emitter, some of it above x's horizon), so an
/// estimate that divides by it stays unbiased; near the emitter it is only a guide. It
/// reads only the emitter's own record (no polygon, no square root).
#[inline]
fn guide(em: &Emitter, x: DVec3, n: DVec3) -> f64 {
    let d = em.centroid - x;
    let cy = -em.normal.dot(d);
    let hx = n.dot(d) + em.radius;
    if cy <= 0.0 || hx <= 0.0 {
        return 0.0;
    }
    let r2 = d.length_squared();
    (hx * cy * em.area / (std::f64::consts::PI * r2 * r2)).min(1.0)
}

/// An area-uniform point on a convex polygon for (u, v) ∈ [0,1)², keeping stratification.
#[inline]
pub fn sample_polygon(v: &[DVec3], cdf: &[f64], u: f64, w: f64) -> DVec3 {
    let total = *cdf.last().unwrap();
    let t = u * total;
    let mut k = 0;
    while k + 1 < cdf.len() && t > cdf[k] {
        k += 1;
    }
    let lo = if k == 0 { 0.0 } else { cdf[k - 1] };
    let uu = ((t - lo) / (cdf[k] - lo).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
    let su = uu.sqrt();
    let (a, b, c) = (v[0], v[k + 1], v[k + 2]);
    a * (1.0 - su) + b * (su * (1.0 - w)) + c * (su * w)
}

/// Direct irradiance at `x` (normal `n`, on polygon `own`) from every emitter; emitter k
/// is sampled at the points `samples(k)` of [0,1)² (mapped area-uniformly onto it).
/// Returns (irradiance, rays cast).
#[allow(clippy::too_many_arguments)]
pub fn direct_irradiance<'s>(
    scene: &Scene,
    rays: &SceneRays,
    emitters: &[Emitter],
    x: DVec3,
    n: DVec3,
    own: u32,
    samples: impl Fn(usize) -> &'s [(f64, f64)],
) -> (Rgb, u64) {
    let mut h = Rgb::ZERO;
    let mut nrays = 0;
    for (k, em) in emitters.iter().enumerate() {
        if em.polygon == own {
            continue;
        }
        let q = &scene.polygons[em.polygon as usize];
        let f = point_to_polygon(x, n, &q.vertices, q.normal);
        if f <= 0.0 {
            continue;
        }
        let mut seen = Rgb::ZERO;
        let mut tried = 0u32;
        for &(a, b) in samples(k) {
            let y = sample_polygon(&q.vertices, &em.cdf, a, b);
            if n.dot(y - x) <= 0.0 {
                continue;
            }
            tried += 1;
            if rays.visible(x, own, y, em.polygon) {
                seen += em.exitance_at(scene, y);
            }
        }
        nrays += tried as u64;
        h += if tried == 0 { em.exitance * f } else { seen * (f / tried as f64) };
    }
    (h, nrays)
}

/// Emitters above which [`direct_irradiance_sampled`] replaces the per-emitter loop.
pub const LOOP_EMITTERS: usize = 4;

/// Direct irradiance at `x` from many emitters. Shadow rays (one per point of `samples`)
/// pick emitters in proportion to their unoccluded contribution `F·E`, with `F` exact
/// within [`NEAR_RADII`] of an emitter and a cheap guide beyond (`guide`: a point-to-point
/// factor, no contour integral). The first coordinate, stratified, selects the emitter
/// through the cumulative weights and is re-used inside it. The exact `F(dA_x → Q)` of a
/// far emitter is computed only once a ray picks it, and each ray weighs `F·E·V` by the
/// probability of its pick: the estimate is unbiased wherever the weight is nonzero, which
/// is wherever `F` is, and exact for an unoccluded position near its emitters (the furnace).
/// With many emitters a position takes a few contour integrals instead of one per emitter:
/// on the classroom's 24 lamp faces the 512² final gather went from 13.9 to 5.9 s, the
/// image unchanged within noise (BENCHMARKS.md, "Eighth round"). `buf` is scratch space.
#[allow(clippy::too_many_arguments)]
pub fn direct_irradiance_sampled(
    scene: &Scene,
    rays: &SceneRays,
    emitters: &[Emitter],
    x: DVec3,
    n: DVec3,
    own: u32,
    samples: &[(f64, f64)],
    buf: &mut Vec<(f64, f64)>,
) -> (Rgb, u64) {
    buf.clear();
    let mut total = 0.0;
    for em in emitters {
        // Near an emitter the guide is poor: take the exact factor there (then an
        // unoccluded position gets the exact sum, whatever the rays pick). Far ones get the
        // guide; their exact factor is filled in once a ray picks them.
        let (f, g) = if em.polygon == own {
            (0.0, 0.0)
        } else if (em.centroid - x).length_squared() < (NEAR_RADII * em.radius).powi(2) {
            let q = &scene.polygons[em.polygon as usize];
            let f = point_to_polygon(x, n, &q.vertices, q.normal);
            (f, f)
        } else {
            (f64::NAN, guide(em, x, n))
        };
        total += g * crate::luminance(em.exitance).max(1e-300);
        buf.push((f, total));
    }
    if total <= 0.0 || samples.is_empty() {
        return (Rgb::ZERO, 0);
    }
    let mut h = Rgb::ZERO;
    let mut nrays = 0;
    for &(a, b) in samples {
        let t = a * total;
        let k = buf.partition_point(|e| e.1 <= t).min(buf.len() - 1);
        let hi = buf[k].1;
        let lo = if k == 0 { 0.0 } else { buf[k - 1].1 };
        let w = hi - lo;
        if w <= 0.0 {
            continue;
        }
        let em = &emitters[k];
        let q = &scene.polygons[em.polygon as usize];
        if buf[k].0.is_nan() {
            buf[k].0 = point_to_polygon(x, n, &q.vertices, q.normal);
        }
        let f = buf[k].0;
        if f <= 0.0 {
            continue;
        }
        let a2 = ((t - lo) / w).clamp(0.0, 1.0 - 1e-12);
        let y = sample_polygon(&q.vertices, &em.cdf, a2, b);
        // Points of the emitter behind x's horizon are outside the clipped factor f: count
        // them as visible rather than bias the choice of emitter.
        let visible = n.dot(y - x) <= 0.0 || {
            nrays += 1;
            rays.visible(x, own, y, em.polygon)
        };
        if visible {
            // f·E / p with p = w / total.
            h += em.exitance_at(scene, y) * (f * total / w);
        }
    }
    (h / samples.len() as f64, nrays)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use glam::DVec3;

    use super::*;
    use crate::sampling::{rng_for, stratified};
    use crate::scene::{obj, Scene};

    /// A 4 × 4 floor (facing up) under eight small lamps (0.2 × 0.2, facing down, at
    /// heights 1 to 2.4, one of them dimmer) and a 1 × 1 blocker at height 0.5 that casts
    /// partial shadows on the points tested.
    fn room() -> Scene {
        let mut obj = String::from("mtllib m.mtl\nusemtl floor\nv 0 0 0\nv 4 0 0\nv 4 0 4\nv 0 0 4\nf 1 4 3 2\n");
        obj += "usemtl floor\nv 1 0.5 1\nv 2 0.5 1\nv 2 0.5 2\nv 1 0.5 2\nf 5 8 7 6\n";
        let mut v = 8;
        for k in 0..8 {
            let (x, z, y) = (0.5 + 0.4 * k as f64, 0.6 + 0.35 * k as f64, 1.0 + 0.2 * k as f64);
            obj += if k == 5 { "usemtl dim\n" } else { "usemtl lamp\n" };
            for (dx, dz) in [(0.0, 0.0), (0.2, 0.0), (0.2, 0.2), (0.0, 0.2)] {
                obj += &format!("v {} {y} {}\n", x + dx, z + dz);
            }
            obj += &format!("f {} {} {} {}\n", v + 1, v + 2, v + 3, v + 4);
            v += 4;
        }
        let mtl = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 3 3 3\nnewmtl dim\nKd 0 0 0\nKe 0.5 1 2\n";
        let desc = obj::parse_obj(&obj, Path::new("room.obj"), |_, _| obj::parse_mtl(mtl, Path::new("m.mtl"))).unwrap();
        Scene::from_desc(desc).unwrap()
    }

    /// The sampled estimate (emitters picked by the guide far away, by the exact factor
    /// near, the exact factor taken only for those picked) is unbiased: its mean over
    /// many draws matches the per-emitter loop with 32 × 32 shadow rays per emitter, on the
    /// floor in and out of the blocker's shadow and on the blocker's top beside the lamps.
    #[test]
    fn sampled_direct_light_matches_the_loop_over_emitters() {
        let scene = room();
        let rays = SceneRays::new(&scene.polygons);
        let ems = emitters(&scene);
        assert_eq!(ems.len(), 8);
        let up = DVec3::Y;
        for (x, own) in [(DVec3::new(1.4, 0.0, 1.5), 0), (DVec3::new(2.5, 0.0, 2.2), 0), (DVec3::new(1.9, 0.5, 1.9), 1)] {
            let mut rng = rng_for(7, 0);
            let mut fine = Vec::new();
            stratified(32, &mut rng, &mut fine);
            let (exact, _) = direct_irradiance(&scene, &rays, &ems, x, up, own, |_| &fine);
            let (mut sum, mut sum2, runs) = (Rgb::ZERO, 0.0, 200_000);
            let (mut pts, mut buf) = (Vec::new(), Vec::new());
            for run in 0..runs {
                let mut rng = rng_for(11, run);
                stratified(2, &mut rng, &mut pts);
                let (h, _) = direct_irradiance_sampled(&scene, &rays, &ems, x, up, own, &pts, &mut buf);
                sum += h;
                sum2 += crate::luminance(h).powi(2);
            }
            let mean = sum / runs as f64;
            let (m, e) = (crate::luminance(mean), crate::luminance(exact));
            let stderr = ((sum2 / runs as f64 - m * m).max(0.0) / runs as f64).sqrt();
            eprintln!("{x}: sampled {m:.5} ± {stderr:.5}, loop {e:.5}");
            assert!(e > 0.0);
            assert!((m - e).abs() < 4.0 * stderr + 1e-3 * e, "{x}: sampled {m} ± {stderr}, loop {e}");
            assert!((m - e).abs() < 0.01 * e, "{x}: sampled {m}, loop {e}");
            // Colour too: the dim lamp's blue share comes through.
            assert!(((mean.z - exact.z) / exact.z).abs() < 0.02, "{x}: blue {} against {}", mean.z, exact.z);
        }
    }
}
