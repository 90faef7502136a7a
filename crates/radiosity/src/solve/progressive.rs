//! Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988): repeatedly
//! shoot the unshot radiosity ΔB_j of the element with the largest unshot power A_j·ΔB_j
//! (Southwell iteration):
//!
//! ```text
//! for every i:  ΔB_i += ρ_i F_ij ΔB_j,  B_i += ρ_i F_ij ΔB_j;   then ΔB_j = 0
//! ```
//!
//! Column `j` of F is read from the transposed rows (exact, no reciprocity assumption, so
//! it converges to the same B as the gathering solvers on any F; compare `shooting`, which
//! uses the power formulation). For display, the ambient term
//! `ρ_i · R · Σ A_k ΔB_k / Σ A_k` with `R = 1/(1 − ρ̄)` estimates the light still unshot
//! (Cohen et al. 1988, §4). One reported iteration = one shot; `max_iterations` caps sweeps
//! of `n` shots. History records are taken after 1, 2, 4 … shots and every n/16 shots; the
//! observer is called after 1, 2, 4 … shots and then every n shots.

use std::borrow::Cow;

use super::{energy_gathering, Monitor, Solution, Solver, StopReason, System};
use crate::{luminance, Result, Rgb};

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let n = sys.len();
    let rows = sys.rows(Solver::Progressive)?;
    let cols = rows.transpose();
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut unshot: Vec<Rgb> = sys.emission.to_vec();
    let emitted = luminance(sys.emitted_power()).max(f64::MIN_POSITIVE);
    let total_area: f64 = sys.area.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let area_rho: Rgb = sys.reflectance.iter().zip(sys.area).map(|(r, a)| *r * *a).sum();
    let interreflection = Rgb::ONE / (Rgb::ONE - area_rho / total_area).max(Rgb::splat(1e-6));
    let ambient = |u: &[Rgb]| -> Vec<Rgb> {
        let area_unshot: Rgb = u.iter().zip(sys.area).map(|(u, a)| *u * *a).sum();
        let amb = interreflection * area_unshot / total_area;
        sys.reflectance.iter().map(|rho| *rho * amb).collect()
    };
    let record_every = (n / 16).max(1);
    let max_shots = mon.opts.max_iterations.saturating_mul(n.max(1));
    // Elements with no open area (wholly inside closed geometry) send no power, but other
    // elements' rows may still gather from them (the inside of one box seen from inside
    // another): for the choice of shooter and the stopping test they count as an element of
    // typical area, or their unshot radiosity would never be passed on and progressive
    // would differ from direct.
    let (sum, count) = sys.area.iter().filter(|a| **a > 0.0).fold((0.0, 0usize), |(s, c), a| (s + a, c + 1));
    let typical = if count == 0 { 1.0 } else { sum / count as f64 };
    let weight: Vec<f64> = sys.area.iter().map(|a| if *a > 0.0 { *a } else { typical }).collect();
    let power = |i: usize, u: &[Rgb]| weight[i] * luminance(u[i]);
    let mut shots = 0usize;
    let mut residual;
    let stop = loop {
        // Find the shooter and the total unshot power in one pass.
        let mut best = 0usize;
        let mut best_p = -1.0;
        let mut total = 0.0;
        for i in 0..n {
            let p = power(i, &unshot);
            total += p;
            if p > best_p {
                best_p = p;
                best = i;
            }
        }
        residual = total / emitted;
        let pow2 = shots.is_power_of_two() && shots < n;
        if shots > 0 && (pow2 || shots % record_every == 0) {
            mon.watch(residual, Some(&b))?;
            mon.record(shots, shots as f64 / n as f64, residual);
        }
        if shots > 0 && (pow2 || shots % n == 0) && mon.observing() {
            let (bb, uu) = (&b, &unshot);
            mon.observe(shots, residual, || {
                Cow::Owned(bb.iter().zip(ambient(uu)).map(|(b, a)| *b + a).collect())
            });
        }
        if residual <= mon.opts.tolerance || best_p <= 0.0 {
            break StopReason::Converged;
        }
        if shots >= max_shots {
            break StopReason::MaxIterations;
        }
        if shots % 64 == 0 {
            if let Some(stop) = mon.interrupted() {
                break stop;
            }
        }
        let db = unshot[best];
        unshot[best] = Rgb::ZERO;
        let (c, v) = cols.row(best);
        for (&i, &f) in c.iter().zip(v) {
            let d = sys.reflectance[i as usize] * db * f as f64;
            b[i as usize] += d;
            unshot[i as usize] += d;
        }
        shots += 1;
    };
    if shots > 0 && !(shots.is_power_of_two() && shots < n || shots % record_every == 0) {
        mon.record(shots, shots as f64 / n as f64, residual);
    }
    let energy = energy_gathering(sys, &b, Some(&unshot));
    let ambient = ambient(&unshot);
    Ok(Solution { radiosity: b, ambient: Some(ambient), energy, stats: mon.finish(shots, residual, stop, None) })
}
