//! Shooting in the power formulation (Cohen, Chen, Wallace & Greenberg 1988, §3; Cohen &
//! Wallace 1993 §5.3.3): every element keeps its unshot radiosity ΔB; each sweep, every
//! element `j` in turn sends its unshot power `A_j·ΔB_j`, of which the fraction `F_ji`
//! arrives at element `i`:
//!
//! ```text
//! for j = 1..n:   for every i:  ΔB_i += ρ_i F_ji A_j ΔB_j / A_i,  B_i += (same);   ΔB_j = 0
//! ```
//!
//! Only the sender's row of F is read: this is the gathering equation rewritten with
//! reciprocity `A_i F_ij = A_j F_ji`. **Choice and why:** it is the formulation that
//! conserves power by construction — each shot hands on exactly `Σ_i F_ji ≤ 1` of the
//! sender's power, so emitted = absorbed + escaped + unshot holds to rounding — but it
//! solves `B = E + ρ·F̃·B` with `F̃_ij = A_j F_ji / A_i`, which equals F only when F is
//! reciprocal. The point-sampled form factors integrate each row at points of its own
//! receiver, so they are reciprocal only approximately, and on such an operator `shooting`
//! differs from the gathering solvers by the reciprocity error of F. The tests therefore
//! compare it with `direct` on a reciprocal operator (the symmetrised
//! `A_i F'_ij = (A_i F_ij + A_j F_ji)/2`), where both formulations have the same solution;
//! `progressive` reads exact columns of F instead when agreement with gathering on any F
//! is wanted.
//!
//! Reported residual: the unshot power `Σ A_i lum(ΔB_i)`, relative to the emitted power.

use std::borrow::Cow;

use super::{energy_power, Monitor, Solution, Solver, System};
use crate::{luminance, Result, Rgb};

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let rows = sys.rows(Solver::Shooting)?;
    let n = sys.len();
    let emitted = luminance(sys.emitted_power()).max(f64::MIN_POSITIVE);
    let unshot_power = |u: &[Rgb]| u.iter().zip(sys.area).map(|(u, a)| a * luminance(*u)).sum::<f64>() / emitted;
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut unshot: Vec<Rgb> = sys.emission.to_vec();
    let mut residual = unshot_power(&unshot);
    let mut sweep = 0;
    let stop = 'sweeps: loop {
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
            let phi = du * sys.area[j];
            let (c, v) = rows.row(j);
            for (&i, &f) in c.iter().zip(v) {
                let i = i as usize;
                // An element with no open area (inside closed geometry) receives nothing.
                if sys.area[i] <= 0.0 {
                    continue;
                }
                let d = sys.reflectance[i] * phi * (f as f64 / sys.area[i]);
                b[i] += d;
                unshot[i] += d;
            }
        }
        residual = unshot_power(&unshot);
        sweep += 1;
    };
    let energy = energy_power(sys, rows, &b, &unshot);
    Ok(Solution { radiosity: b, ambient: None, energy, stats: mon.finish(sweep, residual, stop, None) })
}
