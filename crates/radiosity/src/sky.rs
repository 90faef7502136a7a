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

use rayon::prelude::*;

use crate::accel::SceneRays;
use crate::mesh::{Mesh, Receivers, FINE_K};
use crate::sampling::{basis, cosine_hemisphere, rng_for, stratified};
use crate::Progress;

/// Rays per element for the exposure, as `axis × axis` stratified directions.
pub const DEFAULT_AXIS: usize = 8;

/// Seed of the exposure's random streams (one per element).
const SEED: u64 = 0x5c1e_5c1e;

/// Sky exposure `S_i` of every element (0 for an element with no open area) and the rays
/// cast: `axis × axis` cosine-distributed stratified directions, each from its own point of
/// the element's open part (area-uniform within a random open cell). Stops early, leaving
/// zeros, when `progress` asks to.
pub fn exposure(mesh: &Mesh, rays: &SceneRays, receivers: &Receivers, axis: usize, progress: &dyn Progress) -> (Vec<f64>, u64) {
    use rand::RngExt;
    let axis = axis.max(1);
    let n = mesh.len();
    const CHUNK: usize = 1024;
    progress.begin("sky exposure", n as u64);
    let mut s = vec![0.0; n];
    let cast: u64 = s
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, out)| {
            if progress.should_stop() {
                return 0;
            }
            let mut dirs = Vec::new();
            let mut cast = 0u64;
            for (k, s) in out.iter_mut().enumerate() {
                let e = c * CHUNK + k;
                let el = &mesh.elements[e];
                let open = receivers.open_cells.get(e).copied().unwrap_or(u64::MAX);
                if open == 0 {
                    continue;
                }
                let mut rng = rng_for(SEED, e as u64);
                stratified(axis, &mut rng, &mut dirs);
                let (t, b) = basis(el.normal);
                let mut seen = 0usize;
                for &(u1, u2) in &dirs {
                    let (ru, rv): (f64, f64) = (rng.random(), rng.random());
                    let (u, v) = if open == u64::MAX {
                        (ru, rv)
                    } else {
                        let cell = rng.random_range(0..open.count_ones());
                        let (u0, v0) = receivers.open_cell(e, cell).expect("an open cell");
                        (u0 + ru / FINE_K as f64, v0 + rv / FINE_K as f64)
                    };
                    let p = el.point(&mesh.positions, u, v);
                    let d = cosine_hemisphere(u1, u2);
                    let dir = t * d.x + b * d.y + el.normal * d.z;
                    if rays.escapes(p.as_vec3(), dir.as_vec3(), Some(el.patch)) {
                        seen += 1;
                    }
                }
                cast += dirs.len() as u64;
                *s = seen as f64 / dirs.len() as f64;
            }
            progress.advance(out.len() as u64);
            cast
        })
        .sum();
    progress.end();
    (s, cast)
}
