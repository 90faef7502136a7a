//! Light from a uniform sky ([`crate::scene::Sky`]): the radiance `L_sky` seen by every ray
//! that leaves the geometry.
//!
//! A surface point with normal `n` receives the irradiance
//!
//! ```text
//! H_sky(x) = ∫_Ω L_sky · V(x, ω) cos θ dω = π · L_sky · S(x),
//! S(x)     = (1/π) ∫_Ω V(x, ω) cos θ dω          (sky exposure, 0 ≤ S ≤ 1)
//! ```
//!
//! with `V(x, ω) = 1` where the ray from `x` in direction `ω` meets no polygon. In the
//! radiosity system the sky is a source: its first reflection `ρ_i · π L_sky · S_i` joins the
//! emitted exitance of element `i`, and every later bounce goes through the transport as
//! usual (Cohen & Wallace 1993, §2.6 for environment light; for a uniform sky `S_i` is the
//! rest of each row, `1 − Σ_j F_ij` for exact factors). The element exposure `S_i` is
//! estimated here with rays (cosine-distributed, stratified directions from points spread
//! over the element's open part), not as `1 − Σ_j F_ij`: the rows' own discretisation error
//! would otherwise let the sky leak into closed rooms. The final gather estimates `S(x)`
//! per pixel with its gather rays ([`crate::render::gather`]).
//!
//! An environment image ([`crate::scene::Environment`]) gives each direction its own
//! radiance: `H_sky(x) = ∫_Ω L_env(ω) V(x, ω) cos θ dω`, estimated per element as π times
//! the mean of `L_env(ω)·V(x, ω)` over [`ENVIRONMENT_AXIS`]² cosine-distributed rays (the
//! image read at the mip level of each ray's share of the hemisphere), and per pixel by the
//! final gather's rays ([`environment_irradiance`]).
//!
//! A sun ([`crate::scene::Sun`]) adds `E_sun · max(0, n·ω) · V(x, ω)` averaged over the
//! directions ω of its disk (uniform in solid angle): per element with rays from points
//! spread over it ([`element_irradiance`]), per pixel with shadow rays in the final gather,
//! so its shadows are sharp (penumbrae as wide as the disk) whatever the mesh.

use rayon::prelude::*;

use glam::DVec3;

use crate::accel::SceneRays;
use crate::mesh::{Mesh, Receivers};
use crate::sampling::Rng;
use crate::sampling::{basis, cosine_hemisphere, rng_for, stratified};
use crate::scene::{Scene, Sun};
use crate::{Progress, Rgb};

/// Rays per element for the exposure, as `axis × axis` stratified directions.
pub const DEFAULT_AXIS: usize = 8;

/// Rays per element under an environment image, as `axis × axis` stratified directions
/// (more than a uniform sky's: the image varies by direction).
pub const ENVIRONMENT_AXIS: usize = 16;

/// Seed of the exposure's random streams (one per element).
const SEED: u64 = 0x5c1e_5c1e;

/// Sky exposure `S_i` of every element (0 for an element with no open area) and the rays
/// cast: `axis × axis` cosine-distributed stratified directions, each from its own point of
/// the element's open part (area-uniform within a random open cell). Stops early, leaving
/// zeros, when `progress` asks to.
pub fn exposure(mesh: &Mesh, rays: &SceneRays, receivers: &Receivers, axis: usize, progress: &dyn Progress) -> (Vec<f64>, u64) {
    let (s, cast) = escaping_mean(mesh, rays, receivers, axis, progress, |_| Rgb::ONE);
    (s.into_iter().map(|x| x.x).collect(), cast)
}

/// Irradiance from an environment image on every element (zero for an element with no
/// open area) and the rays cast: `π · mean(L_env(ω) V(x, ω))` over `axis × axis`
/// cosine-distributed stratified directions, each from its own point of the element's open
/// part, the image filtered over each ray's share `2π/axis²` of the hemisphere.
pub fn environment_irradiance(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    env: &crate::scene::Environment,
    axis: usize,
    progress: &dyn Progress,
) -> (Vec<Rgb>, u64) {
    let share = std::f64::consts::TAU / (axis.max(1) * axis.max(1)) as f64;
    let (h, cast) = escaping_mean(mesh, rays, receivers, axis, progress, |dir| env.radiance(dir, share));
    (h.into_iter().map(|x| x * std::f64::consts::PI).collect(), cast)
}

/// Per element, the mean of `value(ω)·V(x, ω)` over `axis × axis` cosine-distributed
/// stratified directions ω, each from its own point of the element's open part
/// (area-uniform within a random open cell), and the rays cast; 0 for an element with no
/// open area. Stops early, leaving zeros, when `progress` asks to.
fn escaping_mean(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    axis: usize,
    progress: &dyn Progress,
    value: impl Fn(DVec3) -> Rgb + Sync,
) -> (Vec<Rgb>, u64) {
    let axis = axis.max(1);
    let mut out = vec![Rgb::ZERO; mesh.len()];
    let cast = crate::progress::for_each_chunked(&mut out, "sky exposure", progress, Vec::new, |e, out, dirs| {
        let el = &mesh.elements[e];
        if receivers.open_cells.get(e).copied().unwrap_or(u64::MAX) == 0 {
            return 0;
        }
        let mut rng = rng_for(SEED, e as u64);
        stratified(axis, &mut rng, dirs);
        let (t, b) = basis(el.normal);
        let mut sum = Rgb::ZERO;
        for &(u1, u2) in dirs.iter() {
            let p = open_point(mesh, receivers, e, &mut rng);
            let d = cosine_hemisphere(u1, u2);
            let dir = t * d.x + b * d.y + el.normal * d.z;
            if rays.escapes(p.as_vec3(), dir.as_vec3(), Some(el.patch)) {
                sum += value(dir);
            }
        }
        *out = sum / dirs.len() as f64;
        dirs.len() as u64
    });
    (out, cast)
}

/// An area-uniform random point of element `e`'s open part.
#[inline]
fn open_point(mesh: &Mesh, receivers: &Receivers, e: usize, rng: &mut Rng) -> DVec3 {
    use rand::RngExt;
    let (u, v) = receivers.open_uv(e, rng.random(), rng.random(), || rng.random());
    mesh.elements[e].point(&mesh.positions, u, v)
}

/// A direction within the sun's disk for (u1, u2) ∈ [0,1)², uniform in solid angle.
#[inline]
pub fn sun_direction(sun: &Sun, u1: f64, u2: f64) -> DVec3 {
    let cos_max = sun.cos_radius();
    let cos_t = 1.0 - u1 * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * std::f64::consts::PI * u2;
    let (t, b) = basis(sun.direction);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + sun.direction * cos_t).normalize()
}

/// The sun's direct irradiance at `p` (normal `n`, on polygon `patch`) per unit of its
/// irradiance: the mean of `max(0, n·ω) · V(p, ω)` over directions `ω` of the disk through
/// the unit-square points `pts`. Also returns the rays cast.
#[inline]
pub fn sun_factor_at(rays: &SceneRays, sun: &Sun, p: DVec3, n: DVec3, patch: u32, pts: &[(f64, f64)]) -> (f64, u64) {
    if pts.is_empty() || n.dot(sun.direction) <= -0.5 * sun.angular_diameter_deg.to_radians().sin() {
        return (0.0, 0);
    }
    let mut sum = 0.0;
    let mut cast = 0;
    for &(u1, u2) in pts {
        let d = sun_direction(sun, u1, u2);
        let c = n.dot(d);
        if c <= 0.0 {
            continue;
        }
        cast += 1;
        if rays.escapes(p.as_vec3(), d.as_vec3(), Some(patch)) {
            sum += c;
        }
    }
    (sum / pts.len() as f64, cast)
}

/// The irradiance the sky and its sun bring to every element directly (none without a lit
/// sky): `π·L_sky·S_i` (or the environment's, [`environment_irradiance`]) `+ E_sun·⟨max(0, n·ω)·V⟩_i`, the sun's term from `axis × axis` points of
/// the element's open part, each with its own direction in the disk. Also returns the rays.
pub fn element_irradiance(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    progress: &dyn Progress,
) -> (Vec<Rgb>, u64) {
    let Some(sky) = scene.lit_sky() else {
        return (Vec::new(), 0);
    };
    let mut cast = 0;
    let mut h = vec![Rgb::ZERO; mesh.len()];
    if let Some(env) = &sky.environment {
        let (he, n) = environment_irradiance(mesh, rays, receivers, env, ENVIRONMENT_AXIS, progress);
        cast += n;
        for (h, x) in h.iter_mut().zip(he) {
            *h += x;
        }
    } else if sky.radiance.max_element() > 0.0 {
        let (s, n) = exposure(mesh, rays, receivers, DEFAULT_AXIS, progress);
        cast += n;
        for (h, s) in h.iter_mut().zip(s) {
            *h += sky.radiance * (std::f64::consts::PI * s);
        }
    }
    if let Some(sun) = sky.lit_sun() {
        progress.begin("sun", mesh.len() as u64);
        let f: Vec<(f64, u64)> = (0..mesh.len())
            .into_par_iter()
            .map(|e| {
                let el = &mesh.elements[e];
                let open = receivers.open_cells.get(e).copied().unwrap_or(u64::MAX);
                if open == 0 || progress.should_stop() {
                    return (0.0, 0);
                }
                let mut rng = rng_for(SEED ^ 0x5a4e, e as u64);
                let mut dirs = Vec::new();
                stratified(DEFAULT_AXIS, &mut rng, &mut dirs);
                let (mut sum, mut n) = (0.0, 0);
                for &(u1, u2) in &dirs {
                    let p = open_point(mesh, receivers, e, &mut rng);
                    let (f, c) = sun_factor_at(rays, &sun, p, el.normal, el.patch, &[(u1, u2)]);
                    sum += f;
                    n += c;
                }
                (sum / dirs.len() as f64, n)
            })
            .collect();
        progress.end();
        for (h, (f, n)) in h.iter_mut().zip(f) {
            *h += sun.irradiance * f;
            cast += n;
        }
    }
    (h, cast)
}
