//! Jacobi iteration (gathering): `B⁽ᵏ⁺¹⁾ = E + ρ·F·B⁽ᵏ⁾`, starting from `B⁽⁰⁾ = E`.
//!
//! After iteration k, B holds exactly the light that has bounced at most k times — the
//! "light flowing into the scene" sequence. Converges because ρ < 1 and row sums ≤ 1
//! (Cohen & Wallace 1993, §5.3).

use super::{Clock, IterationRecord, Options, Solution, SolveStats, StopReason, System};
use crate::{Progress, Result, Rgb};

pub(super) fn solve(sys: &System, opts: &Options, clock: &Clock, progress: &dyn Progress) -> Result<Solution> {
    let n = sys.len();
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut fb = vec![Rgb::ZERO; n];
    let mut history = Vec::new();
    let mut residual;
    let mut it = 0;
    let stop = loop {
        sys.transport.gather(&b, &mut fb);
        // The residual of the current iterate B⁽ⁱᵗ⁾, from the same product.
        residual = sys.residual_with(&b, &fb);
        if it > 0 {
            history.push(IterationRecord { iteration: it, residual, seconds: clock.seconds() });
            progress.message(&format!("jacobi iteration {it}: residual {residual:.3e}"));
        }
        if residual <= opts.tolerance {
            break StopReason::Converged;
        }
        if it >= opts.max_iterations {
            break StopReason::MaxIterations;
        }
        if progress.should_stop() {
            break StopReason::Interrupted;
        }
        if clock.over_budget() {
            break StopReason::TimeBudget;
        }
        for i in 0..n {
            b[i] = sys.emission[i] + sys.reflectance[i] * fb[i];
        }
        it += 1;
    };
    Ok(Solution {
        radiosity: b,
        ambient: None,
        stats: SolveStats { solver: "jacobi".into(), iterations: it, residual, stop, seconds: clock.seconds(), history },
    })
}
