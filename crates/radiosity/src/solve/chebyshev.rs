//! Chebyshev semi-iteration: Jacobi accelerated by Chebyshev polynomials (Golub & Varga
//! 1961, "Chebyshev semi-iterative methods, successive overrelaxation iterative methods,
//! and second order Richardson iterative methods"; Varga, *Matrix Iterative Analysis*
//! §5.1; Saad, *Iterative Methods for Sparse Linear Systems* §12.3).
//!
//! Jacobi's iteration `B⁽ᵏ⁺¹⁾ = E + G·B⁽ᵏ⁾` with `G = ρF` shrinks the error by the spectral
//! radius `β` of `G` per sweep (0.63 on the classroom, 0.9 in a furnace of ρ = 0.9). `G` is
//! non-negative, so its eigenvalues lie in the disk `|λ| ≤ β`, and with reciprocity
//! (`A_i F_ij = A_j F_ji`) `G` is similar to a symmetric matrix: they are real, in
//! `[−β, β]`. The best polynomial of degree k on that interval, the scaled Chebyshev
//! polynomial, gives the three-term recurrence
//!
//! ```text
//! B⁽ᵏ⁺¹⁾ = ω_{k+1} (E + G·B⁽ᵏ⁾ − B⁽ᵏ⁻¹⁾) + B⁽ᵏ⁻¹⁾
//! ω₁ = 1,  ω₂ = 1 / (1 − β²/2),  ω_{k+1} = 1 / (1 − β² ω_k / 4)
//! ```
//!
//! whose error shrinks by `β / (1 + √(1 − β²))` per sweep (0.36 for β = 0.63, 0.63 for
//! β = 0.9): the same one product `F·B` per sweep as Jacobi, about half the sweeps or
//! fewer. For real eigenvalues in (−1, 1) any `β < 1` converges, an estimate near the true
//! radius fastest. Point-sampled rows and the hierarchical operator are only nearly
//! reciprocal, so their eigenvalues may leave the real axis a little: a residual that
//! rises under the recurrence restarts it from the current iterate, and after
//! [`RESTARTS`] restarts the solve goes on as plain Jacobi. `β` is not known beforehand: the first sweeps are plain Jacobi,
//! whose residual ratio tends to `β` (the power method), per colour channel; once the ratio
//! settles ([`SETTLED`], after at least [`ESTIMATE_MIN`] sweeps, at most [`ESTIMATE_MAX`]) the
//! recurrence starts with `β` a little above it ([`MARGIN`]). Iterates are kept
//! non-negative and below the physical bound (the solution is), never below the Jacobi
//! value of the sweep.
//!
//! Unlike Jacobi's, whose iterates approach the solution from below, an iterate may
//! overshoot it slightly: the energy balance's "unshot" (what the next Jacobi step would
//! add) can then be a small negative share, within the tolerance.
//!
//! The iterates are not "k bounces of light" as Jacobi's are (use `jacobi` to watch light
//! flow into the scene), but they converge to the same solution, and the product that
//! updates `B` also gives the residual of the current iterate, as in Jacobi. Needs only
//! [`Transport::gather`](crate::transport::Transport::gather), so it runs on any operator.

use super::{energy_gathering, gather_sweep, Monitor, Solution, System};
use crate::{Result, Rgb};

/// Plain Jacobi sweeps before the spectral radius may be read from the residual ratio.
pub const ESTIMATE_MIN: usize = 2;

/// Plain Jacobi sweeps after which the ratio is taken, settled or not.
pub const ESTIMATE_MAX: usize = 8;

/// The residual ratio counts as settled once it changes by at most this between sweeps.
pub const SETTLED: f64 = 0.03;

/// `β` is taken this share of the way from the measured ratio towards 1: the ratio
/// approaches the spectral radius from below (Sponza: 0.456, 0.467, 0.474, 0.479 …), and
/// a `β` below the true radius slows the recurrence more than one above it.
pub const MARGIN: f64 = 0.1;

/// Restarts of the recurrence (after a rising residual) before the solve goes on as plain
/// Jacobi.
pub const RESTARTS: usize = 3;

/// Per-channel power residual `Σ A_i |E_i + ρ_i (F·B)_i − B_i|`.
fn channel_residual(sys: &System, b: &[Rgb], fb: &[Rgb]) -> Rgb {
    let mut r = Rgb::ZERO;
    for i in 0..b.len() {
        r += (sys.emission[i] + sys.reflectance[i] * fb[i] - b[i]).abs() * sys.area[i];
    }
    r
}

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let n = sys.len();
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut prev: Vec<Rgb> = b.clone();
    let mut fb = vec![Rgb::ZERO; n];
    let mut it = 0;
    // The last two per-channel residuals and ratios of the Jacobi phase.
    let mut last: Option<Rgb> = None;
    let mut ratio: Option<Rgb> = None;
    // Once started: β² per channel, the last ω, and the recurrence's step.
    let mut cheb: Option<(Rgb, Rgb, usize)> = None;
    // The last residual, and the restarts so far (see RESTARTS).
    let (mut last_residual, mut restarts) = (f64::INFINITY, 0);
    // The solution lies below the physical bound (see `Monitor::bound`); an extrapolated
    // iterate that overshoots it is held there (a projection onto a set that holds the
    // solution; in the furnace the solution is the bound).
    let cap = Rgb::splat(if mon.bound.is_finite() { mon.bound } else { f64::INFINITY });
    let (stop, residual) = loop {
        let (residual, stop) = gather_sweep(sys, mon, it, &b, &mut fb)?;
        if let Some(stop) = stop {
            break (stop, residual);
        }
        // A residual that rises under the recurrence (eigenvalues off the real interval
        // the recurrence assumes, or a clamp that broke it): start it again from this
        // iterate, and after RESTARTS of them go on as plain Jacobi.
        if let Some((_, _, step)) = &mut cheb {
            if *step > 0 && residual > last_residual {
                restarts += 1;
                *step = 0;
            }
        }
        if restarts > RESTARTS {
            cheb = None;
            last = None;
            ratio = None;
        }
        last_residual = residual;
        if cheb.is_none() && restarts <= RESTARTS {
            let r = channel_residual(sys, &b, &fb);
            if let Some(l) = last {
                // Channels with nothing left to converge read the largest ratio of the others.
                let q = |c: f64, p: f64| if p > 0.0 && c.is_finite() { (c / p).min(1.0) } else { f64::NAN };
                let mut now = Rgb::new(q(r.x, l.x), q(r.y, l.y), q(r.z, l.z));
                let top = [now.x, now.y, now.z].into_iter().filter(|v| v.is_finite()).fold(0.0f64, f64::max);
                now = Rgb::new(
                    if now.x.is_finite() { now.x } else { top },
                    if now.y.is_finite() { now.y } else { top },
                    if now.z.is_finite() { now.z } else { top },
                );
                let settled = ratio.is_some_and(|p: Rgb| (now - p).abs().max_element() <= SETTLED);
                if it >= ESTIMATE_MIN && (settled || it >= ESTIMATE_MAX) {
                    let beta = (now + (Rgb::ONE - now) * MARGIN).min(Rgb::splat(0.999));
                    // The sweep below is the recurrence's first (ω₁ = 1, a Jacobi sweep
                    // from `b`): the next one takes ω₂.
                    cheb = Some((beta * beta, Rgb::ONE, 0));
                }
                ratio = Some(now);
            }
            last = Some(r);
        }
        match &mut cheb {
            None => {
                for i in 0..n {
                    prev[i] = b[i];
                    b[i] = sys.emission[i] + sys.reflectance[i] * fb[i];
                }
            }
            Some((beta2, omega, step)) => {
                // ω₁ = 1 (a plain sweep), ω₂ = 1/(1 − β²/2), then 1/(1 − β²ω/4).
                *omega = match *step {
                    0 => Rgb::ONE,
                    1 => Rgb::ONE / (Rgb::ONE - *beta2 * 0.5),
                    _ => Rgb::ONE / (Rgb::ONE - *beta2 * *omega * 0.25),
                };
                *step += 1;
                let w = *omega;
                for i in 0..n {
                    let jacobi = sys.emission[i] + sys.reflectance[i] * fb[i];
                    // Never below the Jacobi value: a sweep that itself breaks the bound
                    // (a diverging system) is left for the monitor to see.
                    let next = (w * (jacobi - prev[i]) + prev[i]).max(Rgb::ZERO).min(cap.max(jacobi));
                    prev[i] = b[i];
                    b[i] = next;
                }
            }
        }
        it += 1;
    };
    let energy = energy_gathering(sys, &b, None);
    Ok(Solution { radiosity: b, ambient: None, energy, stats: mon.finish(it, residual, stop, None) })
}
