//! Jacobi iteration (gathering): `B⁽ᵏ⁺¹⁾ = E + ρ·F·B⁽ᵏ⁾`, starting from `B⁽⁰⁾ = E`.
//!
//! After iteration k, B holds exactly the light that has bounced at most k times — the
//! "light flowing into the scene" sequence: iteration 1 lights only what the emitters see.
//! Converges because ρ < 1 and row sums ≤ 1 (Cohen & Wallace 1993, §5.3). Needs only
//! [`Transport::gather`](crate::transport::Transport::gather), so it runs on any operator;
//! the product that updates B also gives the residual of the current iterate.

use std::borrow::Cow;

use super::{energy_gathering, Monitor, Solution, System};
use crate::{Result, Rgb};

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let n = sys.len();
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut fb = vec![Rgb::ZERO; n];
    let mut it = 0;
    let (stop, residual) = loop {
        sys.transport.gather(&b, &mut fb);
        // The residual of the current iterate B⁽ⁱᵗ⁾, from the same product.
        let residual = sys.residual_with(&b, &fb);
        mon.watch(residual, Some(&b))?;
        if it > 0 {
            mon.record(it, it as f64, residual);
            mon.observe(it, residual, || Cow::Borrowed(&b));
        }
        if let Some(stop) = mon.check(it, residual) {
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
