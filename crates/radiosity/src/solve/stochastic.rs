//! Monte Carlo radiosity without form factors: power is distributed by rays (Neumann,
//! Feda, Kopp & Purgathofer 1994; Sbert 1997; Bekaert 1999, "Hierarchical and stochastic
//! algorithms for radiosity", ch. 5–6). The shared machinery of
//! [`Solver::StochasticJacobi`] and [`Solver::StochasticShooting`]:
//!
//! **Distributing power.** To send the power `Φ_j` of every element (RGB, W), element `j`
//! gets `n_j ≈ N·lum(Φ_j)/Σ lum(Φ)` rays by systematic sampling (one random offset per
//! call; at least one ray for every element with power), each ray carrying `Φ_j / n_j`
//! from an area-uniform point of `j` in a cosine-distributed direction. The first element
//! hit (front side) receives the ray's power; a ray that hits nothing or the back of a
//! one-sided surface has escaped. Rays are cast against the scene's polygons
//! ([`SceneRays`], a few triangles per input polygon, so the cost does not grow with the
//! number of elements) and the element is then found inside the polygon hit with a small
//! uniform grid per patch (`Locator`). The expected power arriving at `i` is `Σ_j Φ_j F_ji`
//! for any choice of `n_j ≥ 1`, so the estimate is unbiased, and all of `Φ` is sent, so
//! power is conserved exactly.
//!
//! **Determinism.** Rays are numbered in element order and cut into fixed batches of
//! [`BATCH`] rays; batch `k` of call `stream` draws from `rng_for(seed ^ mix(stream), k)`,
//! and deposits are added in ray order after the parallel tracing, so results are
//! identical whatever the thread count.
//!
//! **Error estimate.** Each solver runs [`REPLICAS`] independent chains with `N /
//! REPLICAS` rays each and returns their mean; the spread of the replicas gives the
//! variance of that mean per element, reported as the relative RMS error
//! `sqrt(Σ A_i Var(lum B_i) / Σ A_i lum(B_i)²)` (the measure of
//! [`relative_difference`](super::relative_difference)).

use std::borrow::Cow;

use glam::DVec3;
use rand::RngExt;
use rayon::prelude::*;

use super::{EnergyBalance, Monitor, Observer, Options, Solution, Solver};
use crate::accel::SceneRays;
use crate::mesh::{Locator, Mesh, Receivers};
use crate::sampling::{basis, cosine_hemisphere, mix64, rng_for};
use crate::{luminance, Error, Progress, Result, Rgb};

/// Independent replicas whose spread gives the error estimate.
pub const REPLICAS: usize = 8;
/// Rays per random stream (the unit of parallel work).
pub const BATCH: u64 = 1024;
/// Batches traced per parallel pass between interrupt checks.
const GROUP: u64 = 64;

/// What the stochastic solvers work on: the elements, ray casting against the scene's
/// polygons (whose indices are the mesh's patches), the materials, and which part of every
/// element is open (not inside closed geometry).
pub struct RaySystem<'a> {
    /// The elements.
    pub mesh: &'a Mesh,
    /// Closest-hit queries against the scene's polygons.
    pub rays: &'a SceneRays,
    /// Reflectance ρ per element.
    pub reflectance: &'a [Rgb],
    /// Emitted exitance E = π·L_e per element.
    pub emission: &'a [Rgb],
    /// The coverage test's result ([`Receivers::all_open`] where there is none).
    pub receivers: &'a Receivers,
    /// Area per element over which it sends and receives
    /// ([`RaySystem::participating_areas`]).
    pub area: &'a [f64],
}

impl RaySystem<'_> {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.emission.len()
    }
    /// True if there are none.
    pub fn is_empty(&self) -> bool {
        self.emission.is_empty()
    }
    /// The area over which every element sends and receives: its open area where it has
    /// one, else (wholly covered, by the coverage test inside closed geometry) its whole
    /// area. A partly covered element takes part through its open cells only (see
    /// [`Shooter::distribute`]). A wholly covered one takes part in full, as its gathered
    /// row does in the deterministic system: it is either the inside of a closed cavity, or
    /// a surface that faces back faces only (the outside of a room wound inwards), and in
    /// both cases what it exchanges is light like any other.
    pub fn participating_areas(mesh: &Mesh, receivers: &Receivers) -> Vec<f64> {
        mesh.elements.iter().zip(&receivers.open_fraction).map(|(e, f)| if *f > 0.0 { e.area * f } else { e.area }).collect()
    }

    /// What the power `arrived` at element `i` does: `(ΔB, absorbed)`.
    pub(crate) fn receive(&self, i: usize, arrived: Rgb) -> (Rgb, Rgb) {
        let rho = self.reflectance[i];
        (rho * arrived / self.area[i].max(f64::MIN_POSITIVE), (Rgb::ONE - rho) * arrived)
    }
}

/// Receiver code of a ray that landed on a covered cell of a partly covered element.
const COVERED: u32 = u32::MAX - 1;

/// The default rays per iteration for `n` elements: 500 per element, at least 200 000.
pub fn default_rays(n: usize) -> u64 {
    (500 * n as u64).max(200_000)
}

/// Solves with a stochastic `solver`, calling `observer` (if any) after every iteration.
pub fn solve(
    solver: Solver,
    sys: &RaySystem,
    opts: &Options,
    progress: &dyn Progress,
    observer: Option<&mut Observer<'_>>,
) -> Result<Solution> {
    let n = sys.len();
    if sys.mesh.len() != n || sys.reflectance.len() != n || sys.area.len() != n || sys.receivers.open_cells.len() != n {
        return Err(Error::Invalid("stochastic solve: system sizes disagree".into()));
    }
    let mut mon = Monitor::new(solver, opts, progress, observer);
    match solver {
        Solver::StochasticJacobi => super::stochastic_jacobi::solve(sys, &mut mon),
        Solver::StochasticShooting => super::stochastic_shooting::solve(sys, &mut mon),
        _ => Err(Error::Invalid(format!("the {solver} solver is deterministic: use solve::solve"))),
    }
}

/// Power arriving at every element from one distribution.
pub(crate) struct Deposit {
    /// Power received per element (before reflection), RGB.
    pub received: Vec<Rgb>,
    /// Power that arrived nowhere.
    pub escaped: Rgb,
    /// Rays cast.
    pub rays: u64,
}

/// Casts the rays of [`Deposit`]s.
pub(crate) struct Shooter<'a> {
    sys: &'a RaySystem<'a>,
    locator: Locator,
    seed: u64,
    /// Origin offset along the normal, against self-intersection at shared edges.
    eps: f64,
}

impl<'a> Shooter<'a> {
    pub(crate) fn new(sys: &'a RaySystem<'a>, seed: u64) -> Self {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in &sys.mesh.positions {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let diag = if lo.x <= hi.x { (hi - lo).length() } else { 1.0 };
        Shooter { sys, locator: Locator::new(sys.mesh), seed, eps: 1e-5 * diag }
    }

    /// Sends `power[j]` from every element along about `rays` rays (see the module docs);
    /// `stream` names this call's random streams. None if `stop()` said so between groups.
    pub(crate) fn distribute(&self, power: &[Rgb], rays: u64, stream: u64, stop: &dyn Fn() -> bool) -> Option<Deposit> {
        let n = power.len();
        let weight: Vec<f64> = power.iter().map(|p| luminance(*p).max(0.0)).collect();
        let total: f64 = weight.iter().sum();
        let mut received = vec![Rgb::ZERO; n];
        if total <= 0.0 {
            return Some(Deposit { received, escaped: Rgb::ZERO, rays: 0 });
        }
        // Systematic sampling of the ray counts, at least one per element with power.
        let stream_seed = self.seed ^ mix64(stream);
        let offset: f64 = rng_for(stream_seed, u64::MAX).random();
        let scale = rays as f64 / total;
        let mut first = Vec::with_capacity(n + 1);
        first.push(0u64);
        let mut cum = 0.0;
        let mut prev = offset.floor() as u64;
        for &w in &weight {
            cum += w * scale;
            let next = (cum + offset).floor() as u64;
            let mut count = next.saturating_sub(prev);
            prev = next;
            if w > 0.0 && count == 0 {
                count = 1;
            }
            let last = *first.last().unwrap_or(&0);
            first.push(last + count);
        }
        let total_rays = first[n];
        let ray_power: Vec<Rgb> = (0..n)
            .map(|j| {
                let c = first[j + 1] - first[j];
                if c > 0 {
                    power[j] / c as f64
                } else {
                    Rgb::ZERO
                }
            })
            .collect();
        let batches = total_rays.div_ceil(BATCH);
        let mut escaped = Rgb::ZERO;
        let mut g = 0;
        while g < batches {
            if stop() {
                return None;
            }
            let end = (g + GROUP).min(batches);
            let hits: Vec<Vec<(u32, u32)>> =
                (g..end).into_par_iter().map(|k| self.trace_batch(k, &first, total_rays, stream_seed)).collect();
            for batch in hits {
                for (sender, receiver) in batch {
                    let w = ray_power[sender as usize];
                    if receiver >= COVERED {
                        escaped += w;
                    } else {
                        received[receiver as usize] += w;
                    }
                }
            }
            g = end;
        }
        Some(Deposit { received, escaped, rays: total_rays })
    }

    /// Traces batch `k`: (sender, receiver or u32::MAX) per ray, in ray order.
    fn trace_batch(&self, k: u64, first: &[u64], total: u64, stream_seed: u64) -> Vec<(u32, u32)> {
        let mesh = self.sys.mesh;
        let (start, end) = (k * BATCH, ((k + 1) * BATCH).min(total));
        let mut rng = rng_for(stream_seed, k);
        let recv = self.sys.receivers;
        let mut out = Vec::with_capacity((end - start) as usize);
        // The element owning ray `start`.
        let mut j = first.partition_point(|&f| f <= start) - 1;
        for r in start..end {
            while first[j + 1] <= r {
                j += 1;
            }
            let e = &mesh.elements[j];
            let (u, v, u1, u2): (f64, f64, f64, f64) = (rng.random(), rng.random(), rng.random(), rng.random());
            // A partly covered element sends from its open cells only, in proportion to
            // their (equal) areas: sent from its whole area, the covered part poured power
            // into the inside of the solid it touches (issue 9).
            let (u, v) = recv.open_uv(j, u, v, || rng.random());
            let x = e.point(&mesh.positions, u, v);
            let (t, b) = basis(e.normal);
            let d = cosine_hemisphere(u1, u2);
            let dir = t * d.x + b * d.y + e.normal * d.z;
            let origin = x + e.normal * self.eps;
            // A planar patch cannot be hit by a ray leaving its front side. Of a two-sided
            // pair (two coincident copies) the copy facing the ray is hit: with plain
            // `closest` the tie went to either, and two-sided scenes lost half their light
            // into "escaped" (issue 9).
            let receiver = match self.sys.rays.closest_facing(origin.as_vec3(), dir.as_vec3(), f32::INFINITY, Some(e.patch)) {
                Some((h, patch)) => {
                    let normal = mesh.elements[mesh.patches[patch as usize].first as usize].normal;
                    if normal.dot(dir) < 0.0 {
                        let hit = origin + dir * h.t as f64;
                        let r = self.locator.locate(mesh, patch, hit);
                        let cells = recv.open_cells.get(r as usize).copied().unwrap_or(u64::MAX);
                        if cells != u64::MAX && cells != 0 && {
                            let (hu, hv) = mesh.elements[r as usize].parameters(&mesh.positions, hit);
                            !recv.open_at(r as usize, hu, hv)
                        } {
                            // Landed on the covered part of an element whose radiosity is
                            // that of its open part: lost, as in the deterministic books.
                            COVERED
                        } else {
                            r
                        }
                    } else {
                        u32::MAX
                    }
                }
                None => u32::MAX,
            };
            out.push((j as u32, receiver));
        }
        out
    }
}


/// One independent chain of a stochastic solver.
#[derive(Clone, Debug)]
pub(crate) struct Replica {
    /// Radiosity estimate.
    pub b: Vec<Rgb>,
    /// Shooting: unshot radiosity; Jacobi: the last increment `B⁽ᵏ⁾ − B⁽ᵏ⁻¹⁾`.
    pub unshot: Vec<Rgb>,
    /// Power absorbed (shooting: so far; Jacobi: in the last iteration).
    pub absorbed: Rgb,
    /// Power escaped (as `absorbed`).
    pub escaped: Rgb,
}

impl Replica {
    pub(crate) fn new(emission: &[Rgb]) -> Self {
        Replica { b: emission.to_vec(), unshot: emission.to_vec(), absorbed: Rgb::ZERO, escaped: Rgb::ZERO }
    }
}

/// The mean radiosity of the replicas.
pub(crate) fn mean(reps: &[Replica]) -> Vec<Rgb> {
    let n = reps[0].b.len();
    let k = reps.len() as f64;
    (0..n).map(|i| reps.iter().map(|r| r.b[i]).sum::<Rgb>() / k).collect()
}

/// The relative RMS error estimate of the replicas' mean (see the module docs).
pub(crate) fn error_estimate(reps: &[Replica], area: &[f64], mean: &[Rgb]) -> f64 {
    let m = reps.len() as f64;
    let mut var = 0.0;
    let mut norm = 0.0;
    for i in 0..mean.len() {
        let mu = luminance(mean[i]);
        let s2: f64 = reps.iter().map(|r| (luminance(r.b[i]) - mu).powi(2)).sum::<f64>() / (m - 1.0);
        var += area[i] * s2 / m;
        norm += area[i] * mu * mu;
    }
    (var / norm.max(f64::MIN_POSITIVE)).sqrt()
}

/// The mean energy balance of the replicas.
pub(crate) fn energy(reps: &[Replica], emission: &[Rgb], area: &[f64]) -> EnergyBalance {
    let m = reps.len() as f64;
    let emitted: Rgb = emission.iter().zip(area).map(|(e, a)| *e * *a).sum();
    let mut out = EnergyBalance { emitted, ..Default::default() };
    for r in reps {
        out.absorbed += r.absorbed / m;
        out.escaped += r.escaped / m;
        out.unshot += r.unshot.iter().zip(area).map(|(u, a)| *u * *a).sum::<Rgb>() / m;
    }
    out
}

/// Calls the observer with the replicas' mean.
pub(crate) fn observe(mon: &mut Monitor, it: usize, residual: f64, reps: &[Replica]) {
    if mon.observing() {
        mon.observe(it, residual, || Cow::Owned(mean(reps)));
    }
}

/// The random stream of replica `r` in iteration `it`.
pub(crate) fn stream(it: usize, r: usize) -> u64 {
    ((it as u64) << 16) | r as u64
}

/// Packages a finished stochastic solve.
pub(crate) fn finish(
    sys: &RaySystem,
    mon: &mut Monitor,
    reps: &[Replica],
    iterations: usize,
    residual: f64,
    stop: super::StopReason,
) -> Solution {
    let area = sys.area;
    let b = mean(reps);
    let err = error_estimate(reps, area, &b);
    let energy = energy(reps, sys.emission, area);
    Solution { radiosity: b, ambient: None, energy, stats: mon.finish(iterations, residual, stop, Some(err)) }
}
