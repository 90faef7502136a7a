//! Stochastic Jacobi radiosity (Neumann, Feda, Kopp & Purgathofer 1994, "A new stochastic
//! radiosity method for highly complex scenes"; Bekaert 1999 §6.2 "regular" stochastic
//! Jacobi): the Jacobi step `B⁽ᵏ⁺¹⁾ = E + ρ·F·B⁽ᵏ⁾` with the product `F·B⁽ᵏ⁾` estimated
//! by rays that carry the *whole* power `A_j B_j⁽ᵏ⁾` of every element
//! ([`super::stochastic`]); no form factor is ever stored.
//!
//! Starting from `B⁽⁰⁾ = E`, iteration k holds k bounces in expectation. Unlike the
//! incremental variant (`stochastic-shooting`) every iteration re-estimates all of B, so
//! the noise of early iterations does not stay in the result, at the price of sending all
//! the power each time (rays per iteration ∝ `Σ A B`, every ray carrying about
//! `emitted / N`). Reported residual: the estimated residual power
//! `|Σ_i A_i lum(B_i⁽ᵏ⁺¹⁾ − B_i⁽ᵏ⁾)|` relative to the emitted power, whose expectation is
//! the deterministic residual. It cannot fall below the noise of its own estimate, so the
//! solver also stops (as converged) once it is within two standard errors of zero across
//! the replicas: further iterations would only change the noise. (Neumann's averaging of
//! the iterates after that point is not done: more rays per iteration lower the noise.)

use super::stochastic::{default_rays, finish, observe, stream, RaySystem, Replica, Shooter, REPLICAS};
use super::{Monitor, Solution, StopReason};
use crate::{luminance, Result, Rgb};

pub(super) fn solve(sys: &RaySystem, mon: &mut Monitor) -> Result<Solution> {
    let n = sys.len();
    let area = sys.area;
    let shooter = Shooter::new(sys, mon.opts.seed);
    let rays = mon.opts.rays.unwrap_or_else(|| default_rays(n));
    let per_replica = (rays / REPLICAS as u64).max(1);
    let emitted_power: Rgb = sys.emission.iter().zip(area).map(|(e, a)| *e * *a).sum();
    let emitted = luminance(emitted_power).max(f64::MIN_POSITIVE);
    // B⁽⁰⁾ = E with "last increment" E: nothing has been passed on yet.
    let mut reps = vec![Replica::new(sys.emission); REPLICAS];
    let mut residual = 1.0;
    let mut at_noise_level = false;
    let mut it = 0;
    let stop = 'iterations: loop {
        mon.watch(residual, None)?;
        if it > 0 {
            mon.record(it, it as f64, residual);
            observe(mon, it, residual, &reps);
        }
        if let Some(stop) = mon.check(it, residual) {
            break stop;
        }
        if at_noise_level {
            break StopReason::Converged;
        }
        let mut deposits = Vec::with_capacity(REPLICAS);
        for (r, rep) in reps.iter().enumerate() {
            let power: Vec<Rgb> = rep.b.iter().zip(area).map(|(b, a)| *b * *a).collect();
            let fraction = power.iter().map(|p| luminance(*p)).sum::<f64>() / emitted;
            let count = ((per_replica as f64 * fraction).ceil() as u64).max(1);
            let stopper = || mon.interrupted().is_some();
            match shooter.distribute(&power, count, stream(it, r), &stopper) {
                Some(d) => deposits.push(d),
                None => break 'iterations mon.interrupted().unwrap_or(StopReason::Interrupted),
            }
        }
        let mut residuals = Vec::with_capacity(REPLICAS);
        for (rep, d) in reps.iter_mut().zip(deposits) {
            mon.rays += d.rays;
            rep.escaped = d.escaped;
            rep.absorbed = Rgb::ZERO;
            let mut change = Rgb::ZERO;
            for i in 0..n {
                let (reflected, absorbed) = sys.receive(i, d.received[i]);
                rep.absorbed += absorbed;
                let new = sys.emission[i] + reflected;
                rep.unshot[i] = new - rep.b[i];
                change += rep.unshot[i] * area[i];
                rep.b[i] = new;
            }
            residuals.push(luminance(change) / emitted);
        }
        let m = residuals.len() as f64;
        let mean = residuals.iter().sum::<f64>() / m;
        let se = (residuals.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (m - 1.0) / m).sqrt();
        residual = mean.abs();
        at_noise_level = residual <= 2.0 * se;
        it += 1;
    };
    Ok(finish(sys, mon, &reps, it, residual, stop))
}
