//! Direct light from emitting polygons at a surface point, exact up to visibility:
//!
//! ```text
//! H_direct(x) = Σ_emitters π·L_e,Q · F(dA_x → Q) · V̂(x, Q)
//! ```
//!
//! with `F(dA_x → Q)` the contour integral ([`crate::form_factor::analytic::point_factor`]) and `V̂` the fraction
//! of stratified shadow rays that reach the emitter (many emitters: rays picked in
//! proportion to each one's unoccluded contribution). Used by the final gather
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
            for k in 1..v.len() - 1 {
                acc += 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length();
                cdf.push(acc);
            }
            Some(Emitter { polygon: i as u32, exitance: m.exitance(), textured: m.emission_texture.is_some(), cdf })
        })
        .collect()
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

/// Direct irradiance at `x` from many emitters: the exact unoccluded factor to every
/// emitter is computed, then the shadow rays (one per point of `samples`) pick emitters in
/// proportion to their unoccluded contribution (the first coordinate, stratified, selects
/// the emitter through the cumulative weights and is re-used inside it), so the estimate
/// is unbiased and rays go where the light comes from. `buf` is scratch space.
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
        let f = if em.polygon == own {
            0.0
        } else {
            let q = &scene.polygons[em.polygon as usize];
            point_to_polygon(x, n, &q.vertices, q.normal)
        };
        let w = f * crate::luminance(em.exitance).max(1e-300);
        total += w;
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
        let (f, hi) = buf[k];
        let lo = if k == 0 { 0.0 } else { buf[k - 1].1 };
        let w = hi - lo;
        if w <= 0.0 {
            continue;
        }
        let em = &emitters[k];
        let q = &scene.polygons[em.polygon as usize];
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
