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
            let cdf = fan_cdf(v);
            let acc = *cdf.last().unwrap();
            let moment: DVec3 = (1..v.len() - 1).map(|k| 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length() * (v[0] + v[k] + v[k + 1]) / 3.0).sum();
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

/// Cumulative areas of the fan triangles `(v[0], v[k], v[k+1])` of a convex polygon: what
/// [`sample_polygon`] reads.
pub fn fan_cdf(v: &[DVec3]) -> Vec<f64> {
    let mut acc = 0.0;
    (1..v.len() - 1)
        .map(|k| {
            acc += 0.5 * (v[k] - v[0]).cross(v[k + 1] - v[0]).length();
            acc
        })
        .collect()
}

/// An area-uniform point on a convex polygon for (u, v) ∈ [0,1)², keeping stratification
/// (`cdf`: [`fan_cdf`]).
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

/// The lamp choice of [`direct_irradiance_sampled`]: each emitter's weight `F·E` (`F` exact
/// within [`NEAR_RADII`] of the emitter, [`guide`] beyond), cumulated, built at one point
/// `x₀` and reused for later points `x` of the same polygon near it. Only the weights'
/// positivity matters for an unbiased estimate (each ray divides by its pick's
/// probability): a weight must be nonzero wherever `F(dA_x → Q)` is. `x` and `x₀` share the
/// tangent plane (same polygon, same normal), so they share the horizon; and no emitter's
/// plane passes between them ([`EmitterChoice::reach`]), so they are in front of the same
/// emitters. The positions of one pixel take the table once instead of one loop over every
/// emitter each (24 lamps on the classroom). [`EmitterChoice::reset`] forgets it (a new
/// pixel).
#[derive(Clone, Debug, Default)]
pub struct EmitterChoice {
    built: bool,
    own: u32,
    at: DVec3,
    n: DVec3,
    /// Distance from `at` below which the table may be reused: no emitter's plane is
    /// nearer, and at most a quarter of the nearest emitter's distance (the weights stay a
    /// good guide).
    reach: f64,
    /// Cumulative weights, one per emitter.
    cum: Vec<f64>,
    /// Exact factors of the emitters picked at the current point.
    picked: Vec<(u32, f64)>,
}

impl EmitterChoice {
    /// Forgets the table: the next point builds its own.
    pub fn reset(&mut self) {
        self.built = false;
    }

    /// Builds the table at `x` (normal `n`, on polygon `own`).
    fn build(&mut self, scene: &Scene, emitters: &[Emitter], x: DVec3, n: DVec3, own: u32) {
        self.cum.clear();
        let mut total = 0.0;
        let mut reach = f64::INFINITY;
        for em in emitters {
            let d = em.centroid - x;
            // Near an emitter the guide is poor: take the exact factor there (then an
            // unoccluded position gets nearly the exact sum, whatever the rays pick).
            let g = if em.polygon == own {
                0.0
            } else if d.length_squared() < (NEAR_RADII * em.radius).powi(2) {
                let q = &scene.polygons[em.polygon as usize];
                point_to_polygon(x, n, &q.vertices, q.normal)
            } else {
                guide(em, x, n)
            };
            reach = reach.min(em.normal.dot(d).abs()).min(0.25 * d.length());
            total += g * crate::luminance(em.exitance).max(1e-300);
            self.cum.push(total);
        }
        (self.built, self.own, self.at, self.n, self.reach) = (true, own, x, n, reach);
    }

    /// Whether the table built at `at` serves `x` (see the type's docs).
    fn serves(&self, x: DVec3, n: DVec3, own: u32) -> bool {
        self.built && self.own == own && self.n == n && (x - self.at).length_squared() < self.reach * self.reach
    }
}

/// Direct irradiance at `x` from many emitters. Shadow rays (one per point of `samples`)
/// pick emitters in proportion to their unoccluded contribution `F·E`, with `F` exact
/// within [`NEAR_RADII`] of an emitter and a cheap guide beyond (`guide`: a point-to-point
/// factor, no contour integral), the weights taken at a point of the same polygon nearby
/// ([`EmitterChoice`], built here when `choice` holds none that serves `x`). The first
/// coordinate, stratified, selects the emitter through the cumulative weights and is re-used
/// inside it. The exact `F(dA_x → Q)` of an emitter is computed only once a ray picks it,
/// and each ray weighs `F·E·V` by the probability of its pick: the estimate is unbiased
/// wherever the weight is nonzero, which is wherever `F` is, and exact for an unoccluded
/// position near its emitters where the table was built (the furnace). With many emitters a
/// position takes a few contour integrals instead of one per emitter: on the classroom's 24
/// lamp faces the 512² final gather went from 13.9 to 5.9 s, the image unchanged within
/// noise (BENCHMARKS.md, "Eighth round").
#[allow(clippy::too_many_arguments)]
pub fn direct_irradiance_sampled(
    scene: &Scene,
    rays: &SceneRays,
    emitters: &[Emitter],
    x: DVec3,
    n: DVec3,
    own: u32,
    samples: &[(f64, f64)],
    choice: &mut EmitterChoice,
) -> (Rgb, u64) {
    if !choice.serves(x, n, own) {
        choice.build(scene, emitters, x, n, own);
    }
    let cum = &choice.cum;
    let total = cum.last().copied().unwrap_or(0.0);
    if total <= 0.0 || samples.is_empty() {
        return (Rgb::ZERO, 0);
    }
    let picked = &mut choice.picked;
    picked.clear();
    let mut h = Rgb::ZERO;
    let mut nrays = 0;
    for &(a, b) in samples {
        let t = a * total;
        let k = cum.partition_point(|&c| c <= t).min(cum.len() - 1);
        let hi = cum[k];
        let lo = if k == 0 { 0.0 } else { cum[k - 1] };
        let w = hi - lo;
        if w <= 0.0 {
            continue;
        }
        let em = &emitters[k];
        let q = &scene.polygons[em.polygon as usize];
        let f = match picked.iter().find(|p| p.0 == k as u32) {
            Some(p) => p.1,
            None => {
                let f = point_to_polygon(x, n, &q.vertices, q.normal);
                picked.push((k as u32, f));
                f
            }
        };
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
            let (mut pts, mut choice) = (Vec::new(), EmitterChoice::default());
            for run in 0..runs {
                let mut rng = rng_for(11, run);
                stratified(2, &mut rng, &mut pts);
                choice.reset();
                let (h, _) = direct_irradiance_sampled(&scene, &rays, &ems, x, up, own, &pts, &mut choice);
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

    /// Weights built at one point serve its neighbours on the same polygon unbiasedly:
    /// built at x₀ (5 cm away, same floor or blocker top) and reused at x, the mean over many
    /// draws still matches the per-emitter loop at x; and no emitter's plane lies within the
    /// reuse distance of x₀.
    #[test]
    fn lamp_choice_reused_nearby_stays_unbiased() {
        let scene = room();
        let rays = SceneRays::new(&scene.polygons);
        let ems = emitters(&scene);
        let up = DVec3::Y;
        for (x, own) in [(DVec3::new(1.4, 0.0, 1.5), 0), (DVec3::new(2.5, 0.0, 2.2), 0), (DVec3::new(1.9, 0.5, 1.9), 1)] {
            let x0 = x + DVec3::new(0.03, 0.0, -0.04);
            let mut rng = rng_for(7, 0);
            let mut fine = Vec::new();
            stratified(32, &mut rng, &mut fine);
            let (exact, _) = direct_irradiance(&scene, &rays, &ems, x, up, own, |_| &fine);
            let (mut sum, mut sum2, runs) = (0.0, 0.0, 200_000);
            let (mut pts, mut choice) = (Vec::new(), EmitterChoice::default());
            let mut reused = 0;
            for run in 0..runs {
                let mut rng = rng_for(13, run);
                stratified(2, &mut rng, &mut pts);
                choice.reset();
                direct_irradiance_sampled(&scene, &rays, &ems, x0, up, own, &pts, &mut choice);
                for em in &ems {
                    assert!(choice.reach <= em.normal.dot(em.centroid - x0).abs() + 1e-12);
                }
                reused += usize::from(choice.serves(x, up, own));
                let (h, _) = direct_irradiance_sampled(&scene, &rays, &ems, x, up, own, &pts, &mut choice);
                let l = crate::luminance(h);
                sum += l;
                sum2 += l * l;
            }
            assert_eq!(reused, runs as usize, "{x}: the table built 5 cm away was not reused");
            let (m, e) = (sum / runs as f64, crate::luminance(exact));
            let stderr = ((sum2 / runs as f64 - m * m).max(0.0) / runs as f64).sqrt();
            eprintln!("{x}: reused {m:.5} ± {stderr:.5}, loop {e:.5}");
            assert!((m - e).abs() < 4.0 * stderr + 1e-3 * e, "{x}: reused {m} ± {stderr}, loop {e}");
            assert!((m - e).abs() < 0.01 * e, "{x}: reused {m}, loop {e}");
        }
    }

    /// A table built above a lamp's plane (where the lamp, facing down, gives nothing) does
    /// not serve a point of the same wall below it (where it does): the wall point below
    /// builds its own and gets the lamp's light.
    #[test]
    fn lamp_choice_is_not_reused_across_a_lamps_plane() {
        let obj = "usemtl wall\nv 0 0 0\nv 0 0 2\nv 0 3 2\nv 0 3 0\nf 1 4 3 2\nusemtl lamp\nv 0.1 1 0.9\nv 0.3 1 0.9\nv 0.3 1 1.1\nv 0.1 1 1.1\nf 5 6 7 8\n";
        let mtl = "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 3 3 3\n";
        let desc = obj::parse_obj(&format!("mtllib m.mtl\n{obj}"), Path::new("wall.obj"), |_, _| obj::parse_mtl(mtl, Path::new("m.mtl"))).unwrap();
        let scene = Scene::from_desc(desc).unwrap();
        let rays = SceneRays::new(&scene.polygons);
        let ems = emitters(&scene);
        assert_eq!(ems.len(), 1);
        assert!(ems[0].normal.y < -0.99, "the lamp faces down");
        let n = scene.polygons[0].normal;
        let (above, below) = (DVec3::new(0.0, 1.05, 1.0), DVec3::new(0.0, 0.95, 1.0));
        let mut pts = Vec::new();
        stratified(2, &mut rng_for(3, 0), &mut pts);
        let mut choice = EmitterChoice::default();
        let (h_above, _) = direct_irradiance_sampled(&scene, &rays, &ems, above, n, 0, &pts, &mut choice);
        assert_eq!(crate::luminance(h_above), 0.0);
        assert!(!choice.serves(below, n, 0));
        let (h_below, _) = direct_irradiance_sampled(&scene, &rays, &ems, below, n, 0, &pts, &mut choice);
        let f = point_to_polygon(below, n, &scene.polygons[1].vertices, scene.polygons[1].normal);
        assert!(f > 0.0 && crate::luminance(h_below) > 0.0, "below the lamp: {h_below} (F = {f})");
    }

    #[test]
    fn points_on_a_polygon_lie_inside_and_cover_it_evenly() {
        // An L-shaped split is not convex; a unit square fan of two triangles is.
        let sq = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        let mut rng = rng_for(1, 2);
        let mut u = || rand::RngExt::random::<f64>(&mut rng);
        let (mut left, m) = (0usize, 20_000);
        for _ in 0..m {
            let p = super::sample_polygon(&sq, &super::fan_cdf(&sq), u(), u());
            assert!((0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.y) && p.z == 0.0, "{p}");
            left += usize::from(p.x < 0.5);
        }
        let f = left as f64 / m as f64;
        assert!((f - 0.5).abs() < 0.02, "fraction in the left half {f}");
    }
}
