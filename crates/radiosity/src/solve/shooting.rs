//! Shooting (Cohen, Chen, Wallace & Greenberg 1988, §3; Cohen & Wallace 1993 §5.3.3):
//! every element keeps its unshot radiosity ΔB; each sweep, every element `j` in turn
//! passes on all of its unshot radiosity, of which element `i` receives `ρ_i F_ij ΔB_j`:
//!
//! ```text
//! for j = 1..n:   for every i:  ΔB_i += ρ_i F_ij ΔB_j,  B_i += ρ_i F_ij ΔB_j;   ΔB_j = 0
//! ```
//!
//! Column `j` of F is read from the transposed rows, so this solves the very system the
//! gathering solvers solve, `B = E + ρ·F·B`, for *any* F — reciprocal or not — and agrees
//! with `direct` to the tolerance (the tests hold it to 1e-6 on point-sampled factors).
//! **Choice and why:** an earlier version used the power formulation with the sender's row
//! (`ΔB_i += ρ_i F_ji A_j ΔB_j / A_i`), which equals this only when `A_i F_ij = A_j F_ji`;
//! on point-sampled factors, reciprocal only approximately, it differed from `direct` by
//! 6 % on the Cornell box at `--mesh-size 50` (issue 9). What differs from `progressive`
//! is only the order of the shots: in sweeps here, largest unshot power first there.
//!
//! Reported residual: the unshot power `Σ A_i lum(ΔB_i)`, relative to the emitted power.
//! Energy: the gathering balance with the unshot part `ΔB`.

use std::borrow::Cow;

use super::{energy_gathering, Monitor, Solution, Solver, System};
use crate::{luminance, Result, Rgb};

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let rows = sys.rows(Solver::Shooting)?;
    let cols = rows.transpose();
    let n = sys.len();
    let emitted = luminance(sys.emitted_power()).max(f64::MIN_POSITIVE);
    let unshot_power = |u: &[Rgb]| u.iter().zip(sys.area).map(|(u, a)| a * luminance(*u)).sum::<f64>() / emitted;
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut unshot: Vec<Rgb> = sys.emission.to_vec();
    let mut residual = unshot_power(&unshot);
    let mut sweep = 0;
    let stop = 'sweeps: loop {
        mon.watch(residual, Some(&b))?;
        if sweep > 0 {
            mon.record(sweep, sweep as f64, residual);
            mon.observe(sweep, residual, || Cow::Borrowed(&b));
        }
        if let Some(stop) = mon.check(sweep, residual) {
            break stop;
        }
        for j in 0..n {
            // Every shot leaves a consistent state, so a sweep may stop half-way.
            if j % 256 == 255 {
                if let Some(stop) = mon.interrupted() {
                    residual = unshot_power(&unshot);
                    break 'sweeps stop;
                }
            }
            let du = unshot[j];
            if du == Rgb::ZERO {
                continue;
            }
            unshot[j] = Rgb::ZERO;
            let (c, v) = cols.row(j);
            for (&i, &f) in c.iter().zip(v) {
                let i = i as usize;
                let d = sys.reflectance[i] * du * f as f64;
                b[i] += d;
                unshot[i] += d;
            }
        }
        residual = unshot_power(&unshot);
        sweep += 1;
    };
    let energy = energy_gathering(sys, &b, Some(&unshot));
    Ok(Solution { radiosity: b, ambient: None, energy, stats: mon.finish(sweep, residual, stop, None) })
}
