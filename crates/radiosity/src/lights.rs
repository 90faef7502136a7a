//! Direct light from point, spot and directional lights ([`crate::scene::Light`]), exact up
//! to one shadow ray per point:
//!
//! ```text
//! point:        H(x) = I · max(0, n·ω) / r² · V(x, p_L)          ω = (p_L − x)/r
//! spot:         H(x) = I · a(θ) · max(0, n·ω) / r² · V(x, p_L)
//!               a(θ) = clamp((cos θ − cos θ_o)/(cos θ_i − cos θ_o), 0, 1)²   (glTF)
//! directional:  H(x) = E · max(0, n·ω) · V(x, ω)                  ω = −direction
//! ```
//!
//! with θ the angle between the spot's axis and `x − p_L`, θ_i and θ_o its inner and outer
//! cone angles. The spot's falloff is the one KHR_lights_punctual recommends (its
//! implementation note), so a baked spot matches what glTF viewers draw. As for the sky
//! ([`crate::sky`]), a light is a source of the radiosity system through its first
//! reflection: element `i` receives the mean of `H` over its open part (estimated from
//! stratified points, one shadow ray each, [`element_irradiance`]), `ρ_i·H̄_i` joins its
//! emitted exitance, and every later bounce goes through the transport. The final gather
//! evaluates `H` per pixel ([`crate::render::gather`]), so shadows are sharp whatever the
//! mesh.

use glam::DVec3;

use crate::accel::SceneRays;
use crate::mesh::{Mesh, Receivers};
use crate::sampling::{rng_for, stratified};
use crate::scene::{Light, LightKind, Scene};
use crate::{Progress, Rgb};

/// Points per element for its mean irradiance, as `axis × axis` stratified points.
pub const DEFAULT_AXIS: usize = 8;

/// Seed of the element points' random streams (one per element).
const SEED: u64 = 0x1147_1947;

/// The spot falloff `a(θ)` of glTF for `cos θ` (1 on the axis).
#[inline]
pub fn spot_falloff(cos_theta: f64, inner_cone: f64, outer_cone: f64) -> f64 {
    let (ci, co) = (inner_cone.cos(), outer_cone.cos());
    let t = ((cos_theta - co) / (ci - co).max(1e-12)).clamp(0.0, 1.0);
    t * t
}

/// The direct irradiance of `light` at `x` (normal `n`, on polygon `patch`), with its
/// shadow ray. Returns the irradiance and the rays cast (0 or 1).
#[inline]
pub fn irradiance_at(rays: &SceneRays, light: &Light, x: DVec3, n: DVec3, patch: u32) -> (Rgb, u64) {
    match light.kind {
        LightKind::Point { position } | LightKind::Spot { position, .. } => {
            let d = position - x;
            let r2 = d.length_squared();
            if r2 <= 0.0 {
                return (Rgb::ZERO, 0);
            }
            let r = r2.sqrt();
            let cos = n.dot(d) / r;
            if cos <= 0.0 {
                return (Rgb::ZERO, 0);
            }
            let a = match light.kind {
                LightKind::Spot { direction, inner_cone, outer_cone, .. } => {
                    spot_falloff(-direction.dot(d) / r, inner_cone, outer_cone)
                }
                _ => 1.0,
            };
            if a <= 0.0 {
                return (Rgb::ZERO, 0);
            }
            if rays.reaches(x, patch, position) {
                (light.intensity * (a * cos / r2), 1)
            } else {
                (Rgb::ZERO, 1)
            }
        }
        LightKind::Directional { direction } => {
            let cos = -n.dot(direction);
            if cos <= 0.0 {
                return (Rgb::ZERO, 0);
            }
            if rays.escapes(x.as_vec3(), (-direction).as_vec3(), Some(patch)) {
                (light.intensity * cos, 1)
            } else {
                (Rgb::ZERO, 1)
            }
        }
    }
}

/// The direct irradiance of every light at `x` (normal `n`, on polygon `patch`), and the
/// rays cast.
#[inline]
pub fn lights_at(rays: &SceneRays, lights: &[Light], x: DVec3, n: DVec3, patch: u32) -> (Rgb, u64) {
    let mut h = Rgb::ZERO;
    let mut cast = 0;
    for l in lights {
        let (e, r) = irradiance_at(rays, l, x, n, patch);
        h += e;
        cast += r;
    }
    (h, cast)
}

/// The irradiance that light from outside the surfaces brings to every element directly:
/// the sky and its sun ([`crate::sky::element_irradiance`]) plus every [`Light`], the
/// lights' part as the mean over `axis × axis` stratified points of the element's open part.
/// Empty when the scene has no such light. Also returns the rays cast. Stops early, leaving
/// zeros, when `progress` asks to.
pub fn element_irradiance(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    progress: &dyn Progress,
) -> (Vec<Rgb>, u64) {
    if !scene.has_external_light() {
        return (Vec::new(), 0);
    }
    let (mut h, mut cast) = crate::sky::element_irradiance(scene, mesh, rays, receivers, progress);
    h.resize(mesh.len(), Rgb::ZERO);
    if scene.lights.is_empty() {
        return (h, cast);
    }
    cast += crate::progress::for_each_chunked(&mut h, "lights", progress, Vec::new, |e, h, pts| {
        use rand::RngExt;
        let el = &mesh.elements[e];
        if receivers.open_cells.get(e).copied().unwrap_or(u64::MAX) == 0 {
            return 0;
        }
        let mut rng = rng_for(SEED, e as u64);
        stratified(DEFAULT_AXIS, &mut rng, pts);
        let (mut sum, mut cast) = (Rgb::ZERO, 0);
        for &(u, v) in pts.iter() {
            let (u, v) = receivers.open_uv(e, u, v, || rng.random());
            let x = el.point(&mesh.positions, u, v);
            let (l, r) = lights_at(rays, &scene.lights, x, el.normal, el.patch);
            sum += l;
            cast += r;
        }
        *h += sum * (1.0 / pts.len() as f64);
        cast
    });
    (h, cast)
}

/// True if a point or spot light sits inside closed geometry: every one of 64 probe rays
/// from it (a Fibonacci sphere) meets the back of a surface first, or a front that is itself
/// enclosed (the floor under a box without a bottom: every probe from there meets the box's
/// back faces, as the coverage test of [`crate::mesh::Receivers`] decides), so its light
/// reaches no open surface (a lamp placed inside a block by mistake). Never for a
/// directional light. `sides`: per polygon, what each side of a two-sided pair is, as light
/// showed it ([`crate::mesh::Receivers::sides`]; empty: the input winding).
pub fn enclosed(scene: &Scene, rays: &SceneRays, light: &Light, sides: &[crate::mesh::lit_sides::Side]) -> bool {
    let (LightKind::Point { position } | LightKind::Spot { position, .. }) = light.kind else {
        return false;
    };
    let from_behind = |origin: DVec3, dir: DVec3, from: Option<u32>| match rays.closest_facing(
        origin.as_vec3(),
        dir.as_vec3(),
        f32::INFINITY,
        from,
    ) {
        Some((hit, q)) => {
            let p = &scene.polygons[q as usize];
            Err((crate::mesh::coverage::solid_side(scene, sides, q) || p.normal.dot(dir) > 0.0, hit.t as f64, q))
        }
        None => Ok(()),
    };
    let sphere = crate::sampling::fibonacci_sphere;
    const PROBES: u32 = 64;
    (0..PROBES).all(|k| {
        let dir = sphere(k, PROBES);
        match from_behind(position, dir, None) {
            Ok(()) => false,
            Err((true, _, _)) => true,
            Err((false, t, q)) => {
                // A front face: enclosed itself when every probe into its hemisphere meets a back.
                let n = scene.polygons[q as usize].normal;
                let x = position + dir * t;
                (0..PROBES).map(|j| sphere(j, PROBES)).filter(|d| d.dot(n) > 0.05).all(|d| {
                    matches!(from_behind(x, d, Some(q)), Err((true, _, _)))
                })
            }
        }
    })
}

/// Power a light sends out (per channel), or None for a directional light (its power is
/// unbounded: it lights every surface it faces). A spot's is `2π I ∫ a(θ) sin θ dθ = 2π I [(1 − cos θ_i) + (cos θ_i − cos θ_o)/3]`.
pub fn emitted_power(light: &Light) -> Option<Rgb> {
    use std::f64::consts::PI;
    match light.kind {
        LightKind::Point { .. } => Some(light.intensity * (4.0 * PI)),
        LightKind::Spot { inner_cone, outer_cone, .. } => {
            // ∫ a dω = 2π [∫ from cos θ_i to 1 of 1 dc + ∫ from cos θ_o to cos θ_i of
            // ((c − cos θ_o)/(cos θ_i − cos θ_o))² dc] = 2π [(1 − cos θ_i) + (cos θ_i − cos θ_o)/3].
            let (ci, co) = (inner_cone.cos(), outer_cone.cos());
            let band = (ci - co) / 3.0;
            Some(light.intensity * (2.0 * PI * ((1.0 - ci) + band)))
        }
        LightKind::Directional { .. } => None,
    }
}
