//! Progressive refinement radiosity (Cohen, Chen, Wallace & Greenberg 1988): repeatedly
//! shoot the unshot radiosity ΔB_j of the element with the largest unshot power A_j·ΔB_j
//! (Southwell iteration):
//!
//! ```text
//! for every i:  ΔB_i += ρ_i F_ij ΔB_j,  B_i += ρ_i F_ij ΔB_j;   then ΔB_j = 0
//! ```
//!
//! Column `j` of F is read from the transposed rows (exact, no reciprocity assumption, so
//! it converges to the same B as the gathering solvers). For display, the ambient term
//! ρ_i · R · Σ A_k ΔB_k / Σ A_k with R = 1/(1 − ρ̄) estimates the light still unshot.
//! One reported iteration = one shot; `max_iterations` caps sweeps of `n` shots.

use super::{Clock, IterationRecord, Options, Solution, SolveStats, StopReason, System};
use crate::{luminance, Error, Progress, Result, Rgb};

pub(super) fn solve(sys: &System, opts: &Options, clock: &Clock, progress: &dyn Progress) -> Result<Solution> {
    let n = sys.len();
    let rows = sys
        .transport
        .rows()
        .ok_or_else(|| Error::Invalid("progressive refinement needs an operator with explicit rows".into()))?;
    let cols = rows.transpose();
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut unshot: Vec<Rgb> = sys.emission.to_vec();
    let emitted = luminance(sys.emitted_power()).max(f64::MIN_POSITIVE);
    let total_area: f64 = sys.area.iter().sum();
    let mut history = Vec::new();
    let record_every = (n / 16).max(1);
    let max_shots = opts.max_iterations.saturating_mul(n.max(1));
    let mut shots = 0usize;
    let power = |i: usize, u: &[Rgb]| sys.area[i] * luminance(u[i]);
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
        if shots > 0 && (shots % record_every == 0) {
            history.push(IterationRecord { iteration: shots, residual, seconds: clock.seconds() });
            progress.message(&format!("progressive: {shots} shots, unshot power {residual:.3e}"));
        }
        if residual <= opts.tolerance || best_p <= 0.0 {
            break StopReason::Converged;
        }
        if shots >= max_shots {
            break StopReason::MaxIterations;
        }
        if shots % 64 == 0 {
            if progress.should_stop() {
                break StopReason::Interrupted;
            }
            if clock.over_budget() {
                break StopReason::TimeBudget;
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
    if history.last().is_none_or(|r| r.iteration != shots) {
        history.push(IterationRecord { iteration: shots, residual, seconds: clock.seconds() });
    }
    // Ambient term for display.
    let mut area_unshot = Rgb::ZERO;
    let mut area_rho = Rgb::ZERO;
    for i in 0..n {
        area_unshot += unshot[i] * sys.area[i];
        area_rho += sys.reflectance[i] * sys.area[i];
    }
    let rho_avg = area_rho / total_area.max(f64::MIN_POSITIVE);
    let r = Rgb::ONE / (Rgb::ONE - rho_avg).max(Rgb::splat(1e-6));
    let ambient = r * area_unshot / total_area.max(f64::MIN_POSITIVE);
    let ambient: Vec<Rgb> = sys.reflectance.iter().map(|rho| *rho * ambient).collect();
    Ok(Solution {
        radiosity: b,
        ambient: Some(ambient),
        stats: SolveStats {
            solver: "progressive".into(),
            iterations: shots,
            residual,
            stop,
            seconds: clock.seconds(),
            history,
        },
    })
}
