//! Stochastic (incremental) shooting: the Monte Carlo version of shooting radiosity
//! (Bekaert 1999, §6.3 "incremental stochastic Jacobi"; Neumann et al. 1994; estimators
//! after Sbert 1997). Each iteration sends the unshot power `A_j ΔB_j` of *all* elements
//! at once by rays ([`super::stochastic`]) and keeps only what arrives:
//!
//! ```text
//! ΔB_i ← ρ_i · (power arriving at i) / A_i,    B_i += ΔB_i
//! ```
//!
//! so iteration k adds the k-th bounce, as deterministic Jacobi does, without ever storing
//! a form factor. The rays per iteration are proportional to the unshot power (Bekaert's
//! choice: every ray carries about the same power, `emitted / N`), so later bounces cost
//! fewer rays. Reported residual: the unshot power relative to the emitted power. Power
//! is conserved exactly: emitted = absorbed + escaped + unshot in every replica.

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
    let unshot_fraction =
        |r: &Replica| r.unshot.iter().zip(area).map(|(u, a)| a * luminance(*u)).sum::<f64>() / emitted;
    let mean_unshot = |reps: &[Replica]| reps.iter().map(unshot_fraction).sum::<f64>() / reps.len() as f64;
    let mut reps = vec![Replica::new(sys.emission); REPLICAS];
    let mut residual = mean_unshot(&reps);
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
        // All replicas advance, or none (an interrupt keeps the previous iterate).
        let mut deposits = Vec::with_capacity(REPLICAS);
        for (r, rep) in reps.iter().enumerate() {
            let power: Vec<Rgb> = rep.unshot.iter().zip(area).map(|(u, a)| *u * *a).collect();
            let count = ((per_replica as f64 * unshot_fraction(rep)).ceil() as u64).max(1);
            let stopper = || mon.interrupted().is_some();
            match shooter.distribute(&power, count, stream(it, r), &stopper) {
                Some(d) => deposits.push(d),
                None => break 'iterations mon.interrupted().unwrap_or(StopReason::Interrupted),
            }
        }
        for (rep, d) in reps.iter_mut().zip(deposits) {
            mon.rays += d.rays;
            rep.escaped += d.escaped;
            for i in 0..n {
                let (reflected, absorbed) = sys.receive(i, d.received[i]);
                rep.absorbed += absorbed;
                rep.unshot[i] = reflected;
                rep.b[i] += rep.unshot[i];
            }
        }
        residual = mean_unshot(&reps);
        it += 1;
    };
    Ok(finish(sys, mon, &reps, it, residual, stop))
}
