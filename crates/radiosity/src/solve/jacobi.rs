//! Jacobi iteration (gathering): `B⁽ᵏ⁺¹⁾ = E + ρ·F·B⁽ᵏ⁾`, starting from `B⁽⁰⁾ = E`.
//!
//! After iteration k, B holds exactly the light that has bounced at most k times — the
//! "light flowing into the scene" sequence: iteration 1 lights only what the emitters see.
//! Converges because ρ < 1 and row sums ≤ 1 (Cohen & Wallace 1993, §5.3). Needs only
//! [`Transport::gather`](crate::transport::Transport::gather), so it runs on any operator;
//! the product that updates B also gives the residual of the current iterate.

use super::{energy_gathering, gather_sweep, Monitor, Solution, System};
use crate::{Result, Rgb};

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let n = sys.len();
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut fb = vec![Rgb::ZERO; n];
    let mut it = 0;
    let (stop, residual) = loop {
        // The residual of the current iterate B⁽ⁱᵗ⁾, from the same product.
        let (residual, stop) = gather_sweep(sys, mon, it, &b, &mut fb)?;
        if let Some(stop) = stop {
            break (stop, residual);
        }
        for i in 0..n {
            b[i] = sys.emission[i] + sys.reflectance[i] * fb[i];
        }
        it += 1;
    };
    let energy = energy_gathering(sys, &b, None);
    Ok(Solution { radiosity: b, ambient: None, energy, stats: mon.finish(it, residual, stop, None) })
}
