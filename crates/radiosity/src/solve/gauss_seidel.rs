//! Gauss–Seidel iteration (gathering, updated values used at once; Cohen & Greenberg 1985,
//! Cohen & Wallace 1993 §5.3.2):
//!
//! ```text
//! for i = 1..n:   B_i ← E_i + ρ_i Σ_j F_ij B_j      (B_j already updated for j < i)
//! ```
//!
//! Light that arrives at an element early in a sweep is passed on in the same sweep, so it
//! needs fewer sweeps than Jacobi (about half for radiosity matrices). A sweep is serial by
//! nature. The residual after a sweep costs only the upper part of F: with
//! `δ = B_new − B_old`, `r_i = E_i + ρ_i (F B_new)_i − B_new_i = ρ_i Σ_{j≥i} F_ij δ_j`,
//! because row i was gathered with the new values of j < i and the old ones of j ≥ i.

use std::borrow::Cow;

use rayon::prelude::*;

use super::{energy_gathering, Monitor, Solution, System};
use crate::{luminance, Result, Rgb};

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let rows = sys.rows(super::Solver::GaussSeidel)?;
    let n = sys.len();
    let emitted = luminance(sys.emitted_power()).max(f64::MIN_POSITIVE);
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut delta = vec![Rgb::ZERO; n];
    let mut residual = sys.residual(&b);
    let mut sweep = 0;
    let stop = loop {
        mon.watch(residual, Some(&b))?;
        if sweep > 0 {
            mon.record(sweep, sweep as f64, residual);
            mon.observe(sweep, residual, || Cow::Borrowed(&b));
        }
        if let Some(stop) = mon.check(sweep, residual) {
            break stop;
        }
        for i in 0..n {
            let new = sys.emission[i] + sys.reflectance[i] * rows.gather_row(i, &b);
            delta[i] = new - b[i];
            b[i] = new;
        }
        // Residual of the new iterate from the upper part of F (see the module docs);
        // summed in element order so the value does not depend on the thread count.
        let parts: Vec<f64> = (0..n)
            .into_par_iter()
            .with_min_len(64)
            .map(|i| {
                let (c, v) = rows.row(i);
                let start = c.partition_point(|&j| (j as usize) < i);
                let mut acc = Rgb::ZERO;
                for (&j, &f) in c[start..].iter().zip(&v[start..]) {
                    acc += delta[j as usize] * f as f64;
                }
                sys.area[i] * luminance((sys.reflectance[i] * acc).abs())
            })
            .collect();
        residual = parts.iter().sum::<f64>() / emitted;
        sweep += 1;
    };
    let energy = energy_gathering(sys, &b, None);
    Ok(Solution { radiosity: b, ambient: None, energy, stats: mon.finish(sweep, residual, stop, None) })
}
