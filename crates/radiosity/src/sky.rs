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
//! per pixel with its gather rays ([`crate::render::gather`]). Through sky portals
//! ([`crate::scene::Portal`]: a courtyard's opening, a window) both sample the sky in the
//! portals' solid angle instead ([`portal_integral`], Arvo 1995's spherical triangles),
//! their cosine rays taking only the directions outside the portals ([`through_portal`]).
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
use crate::scene::{Portal, Scene, Sun};
use crate::{Progress, Rgb};

/// Rays per element for the exposure, as `axis × axis` stratified directions.
pub const DEFAULT_AXIS: usize = 8;

/// Rays per element under an environment image, as `axis × axis` stratified directions
/// (more than a uniform sky's: the image varies by direction).
pub const ENVIRONMENT_AXIS: usize = 16;

/// Seed of the exposure's random streams (one per element).
const SEED: u64 = 0x5c1e_5c1e;

/// Under sky portals an element's exposure takes `(axis/2)²` cosine rays for the sky
/// outside the portals and as many draws in the portals' solid angle
/// ([`portal_integral`]): half the axis each, a quarter of the rays each. Sponza with its
/// courtyard portal (BENCHMARKS.md, "Sky portals"): the same RMS deviation from 1 024 rays
/// per element as 64 cosine rays (0.0056), with 3.3 M rays instead of 9.3 M, in 0.9 s
/// instead of 1.3–1.5 s.
pub const PORTAL_AXIS_DIVISOR: usize = 2;

/// Sky exposure `S_i` of every element (0 for an element with no open area) and the rays
/// cast: `axis × axis` cosine-distributed stratified directions, each from its own point of
/// the element's open part (area-uniform within a random open cell); under `portals`, the
/// sky through them sampled in their solid angle instead ([`PORTAL_AXIS_DIVISOR`]). Stops
/// early, leaving zeros, when `progress` asks to.
pub fn exposure(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    axis: usize,
    portals: &[Portal],
    progress: &dyn Progress,
) -> (Vec<f64>, u64) {
    let (s, cast) = escaping_mean(mesh, rays, receivers, axis, portals, progress, |_, _| Rgb::ONE);
    (s.into_iter().map(|x| x.x).collect(), cast)
}

/// Irradiance from an environment image on every element (zero for an element with no
/// open area) and the rays cast: `π · mean(L_env(ω) V(x, ω))` over `axis × axis`
/// cosine-distributed stratified directions, each from its own point of the element's open
/// part, the image filtered over each ray's share `2π/axis²` of the hemisphere (under
/// `portals`, as [`exposure`] takes them, over each ray's or draw's share).
pub fn environment_irradiance(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    env: &crate::scene::Environment,
    axis: usize,
    portals: &[Portal],
    progress: &dyn Progress,
) -> (Vec<Rgb>, u64) {
    let (h, cast) = escaping_mean(mesh, rays, receivers, axis, portals, progress, |dir, share| env.radiance(dir, share));
    (h.into_iter().map(|x| x * std::f64::consts::PI).collect(), cast)
}

/// Per element, `(1/π) ∫ value(ω)·V(x, ω) cos θ dω` averaged over its open part: the
/// mean of `value·V` over `axis × axis` cosine-distributed stratified directions ω, each
/// from its own point of the element's open part (area-uniform within a random open cell);
/// under `portals`, `(axis/d)²` such rays for the directions outside them and as many
/// draws in their solid angle, each from its own point ([`portal_integral`], `d` =
/// [`PORTAL_AXIS_DIVISOR`]). `value` takes the direction and its share of the solid angle.
/// Also returns the rays cast; 0 for an element with no open area. Stops early, leaving
/// zeros, when `progress` asks to.
#[allow(clippy::too_many_arguments)]
fn escaping_mean(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    axis: usize,
    portals: &[Portal],
    progress: &dyn Progress,
    value: impl Fn(DVec3, f64) -> Rgb + Sync,
) -> (Vec<Rgb>, u64) {
    let axis = if portals.is_empty() { axis.max(1) } else { (axis / PORTAL_AXIS_DIVISOR).max(1) };
    let share = std::f64::consts::TAU / (axis * axis) as f64;
    let mut out = vec![Rgb::ZERO; mesh.len()];
    let scratch = || (Vec::new(), Vec::new());
    let cast = crate::progress::for_each_chunked(&mut out, "sky exposure", progress, scratch, |e, out, (dirs, tris)| {
        let el = &mesh.elements[e];
        if receivers.open_cells.get(e).copied().unwrap_or(u64::MAX) == 0 {
            return 0;
        }
        let mut rng = rng_for(SEED, e as u64);
        stratified(axis, &mut rng, dirs);
        let (t, b) = basis(el.normal);
        let mut sum = Rgb::ZERO;
        let mut cast = 0;
        for &(u1, u2) in dirs.iter() {
            let p = open_point(mesh, receivers, e, &mut rng);
            let d = cosine_hemisphere(u1, u2);
            let dir = t * d.x + b * d.y + el.normal * d.z;
            // The sky through a portal is the portal draws' below.
            if through_portal(portals, p, dir) {
                continue;
            }
            cast += 1;
            if rays.escapes(p.as_vec3(), dir.as_vec3(), Some(el.patch)) {
                sum += value(dir, share);
            }
        }
        let mut mean = sum / dirs.len() as f64;
        // A portal with no corner in front of the element's plane is behind every point
        // of it (n·p is the same across a flat element): no draws.
        let c0 = el.centroid;
        if portals.iter().any(|q| q.vertices().iter().any(|v| el.normal.dot(*v - c0) > 0.0)) {
            // Each draw from its own point of the element (a stream of their own).
            let mut rng = rng_for(SEED ^ 0x9071_a150, e as u64);
            stratified(axis, &mut rng, dirs);
            let m = dirs.len() as f64;
            let mut through = Rgb::ZERO;
            for &pt in dirs.iter() {
                let p = open_point(mesh, receivers, e, &mut rng);
                let (h, c) = portal_integral(rays, portals, p, el.normal, el.patch, &[pt], tris, |d, s| value(d, s / m));
                through += h;
                cast += c;
            }
            mean += through / (m * std::f64::consts::PI);
        }
        *out = mean;
        cast
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

/// A portal's fan triangle seen from one position: the spherical triangle, the solid angle
/// of the triangles up to and including it, and its portal's index.
pub type PortalTriangle = (crate::sampling::SphericalTriangle, f64, usize);

/// Whether the ray `p + t·dir` (t > 0) passes through one of `portals`.
#[inline]
pub fn through_portal(portals: &[Portal], p: DVec3, dir: DVec3) -> bool {
    portals.iter().any(|q| {
        let (v, n) = (q.vertices(), q.normal());
        let den = n.dot(dir);
        if den == 0.0 {
            return false;
        }
        let t = n.dot(v[0] - p) / den;
        if !(t > 0.0) {
            return false;
        }
        let y = p + dir * t;
        // Inside the convex polygon: on the same side of every edge (either winding).
        let m = v.len();
        let (mut pos, mut neg) = (false, false);
        for k in 0..m {
            let s = n.dot((v[(k + 1) % m] - v[k]).cross(y - v[k]));
            pos |= s > 0.0;
            neg |= s < 0.0;
        }
        !(pos && neg)
    })
}

/// `∫ value(ω) V(ω) cos θ dω` at `p` (normal `n`, on polygon `patch`) over the directions
/// that pass through one of `portals`, with directions drawn uniformly in the solid angle
/// of the portals' fan triangles (Arvo 1995; `sampling::SphericalTriangle`), a
/// triangle picked in proportion to its solid angle by the first coordinate of each of the
/// stratified `pts`: `Ω · mean(value V cos θ)`, `V` whether the ray leaves the scene;
/// `value` takes the direction and each draw's share of the solid angle (an environment
/// image's filter width). A direction drawn from portal j that also passes through an
/// earlier portal counts nothing (the earlier one's draws cover it), so portals that
/// overlap as seen from `p` count their shared sky once. Unbiased whatever the portals
/// cover, with the sky seen in every other direction taken by cosine rays that skip the
/// portals ([`through_portal`]): the final gather's sky (`crate::render::gather`) and the
/// elements' exposure ([`exposure`]). Returns the integral and the rays cast; `tris` is
/// scratch (kept to spare an allocation per position).
#[allow(clippy::too_many_arguments)]
pub fn portal_integral(
    rays: &SceneRays,
    portals: &[Portal],
    p: DVec3,
    n: DVec3,
    patch: u32,
    pts: &[(f64, f64)],
    tris: &mut Vec<PortalTriangle>,
    value: impl Fn(DVec3, f64) -> Rgb,
) -> (Rgb, u64) {
    use crate::sampling::SphericalTriangle;
    // The fan triangles in front of p's tangent plane, with their solid angles cumulated and
    // their portal.
    tris.clear();
    let mut total = 0.0;
    for (j, q) in portals.iter().enumerate() {
        let v = q.vertices();
        if v.iter().all(|c| n.dot(*c - p) <= 0.0) {
            continue;
        }
        for k in 1..v.len() - 1 {
            let dirs = [v[0] - p, v[k] - p, v[k + 1] - p];
            if dirs.iter().any(|d| !(d.length_squared() > 0.0)) {
                continue;
            }
            if let Some(t) = SphericalTriangle::new(dirs[0].normalize(), dirs[1].normalize(), dirs[2].normalize()) {
                total += t.area;
                tris.push((t, total, j));
            }
        }
    }
    if tris.is_empty() || pts.is_empty() {
        return (Rgb::ZERO, 0);
    }
    let share = total / pts.len() as f64;
    let (mut sum, mut nrays) = (Rgb::ZERO, 0);
    for &(u, w) in pts {
        let t = u * total;
        let i = tris.partition_point(|x| x.1 <= t).min(tris.len() - 1);
        let lo = if i == 0 { 0.0 } else { tris[i - 1].1 };
        let uu = ((t - lo) / tris[i].0.area).clamp(0.0, 1.0 - 1e-12);
        let d = tris[i].0.sample(uu, w);
        let c = n.dot(d);
        if c <= 0.0 || through_portal(&portals[..tris[i].2], p, d) {
            continue;
        }
        nrays += 1;
        if rays.escapes(p.as_vec3(), d.as_vec3(), Some(patch)) {
            sum += value(d, share) * c;
        }
    }
    (sum * (total / pts.len() as f64), nrays)
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
        let (he, n) = environment_irradiance(mesh, rays, receivers, env, ENVIRONMENT_AXIS, &sky.portals, progress);
        cast += n;
        for (h, x) in h.iter_mut().zip(he) {
            *h += x;
        }
    } else if sky.radiance.max_element() > 0.0 {
        let (s, n) = exposure(mesh, rays, receivers, DEFAULT_AXIS, &sky.portals, progress);
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
