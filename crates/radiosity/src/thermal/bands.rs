//! Non-grey surfaces by the band-energy approximation (Modest, *Radiative Heat Transfer*,
//! §5.6; Siegel & Howell, *Thermal Radiation Heat Transfer*, ch. 6): the spectrum is split
//! at wavelengths `λ₁ < λ₂ < …` into bands, each surface is grey within a band (its own
//! `ε_b`), and each band is a grey exchange of its share of the blackbody emission,
//!
//! ```text
//! J_ib − (1 − ε_ib) Σⱼ Fᵢⱼ J_jb = ε_ib f_b(Tᵢ) σTᵢ⁴ + (1 − ε_ib) Fᵢ,env f_b(T_env) σT_env⁴
//! f_b(T) = F(λ_b T) − F(λ_{b−1} T),   F(λT) = (15/π⁴) ∫_{C₂/λT}^∞ x³/(eˣ − 1) dx
//! ```
//!
//! (`F` the blackbody fraction below `λT`, `C₂` the second radiation constant). A surface
//! at a given temperature has its emission in every band; a heat-flux or adiabatic surface
//! has one unknown `sᵢ = σTᵢ⁴` shared by the bands, closed by `Σ_b (J_ib − G_ib) = qᵢ`, and
//! its band shares `f_b(Tᵢ)` depend on the temperature being solved for. Each band's
//! matrix `A_b = I − diag(1 − ε_b) F` is factorised once; the flux surfaces' equations
//! reduce to a small system in `s` (their number of unknowns), solved again as the
//! shares are updated until the temperatures stop changing (successive substitution;
//! the shares vary slowly with T, so a few iterations).
//!
//! With the same ε in every band the solution is the grey one (the shares sum to 1).

use faer::Mat;

use super::{lu_solve_dense, singular, ElementSolution, STEFAN_BOLTZMANN};
use crate::scene::{Boundary, ThermalSpec};
use crate::transport::DenseMatrix;
use crate::{Error, Result};

/// The second radiation constant `C₂ = hc/k`, µm·K (CODATA 2018).
pub const C2: f64 = 14_387.768_775;

/// Most bands a solve may have.
pub const MAX_BANDS: usize = 64;

/// Fraction of a blackbody's emission at wavelengths below `λ` at temperature `T`, given
/// `λT` in µm·K: `F(λT) = (15/π⁴) ∫_{C₂/λT}^∞ x³/(eˣ − 1) dx` (0 at 0, 1 at infinity).
/// Series: `Σₙ e^{−nξ}/n (ξ³ + 3ξ²/n + 6ξ/n² + 6/n³)` for `ξ = C₂/λT ≥ 2`, else one minus
/// the Bernoulli series of the integral from 0 (both to ~1e-15).
pub fn blackbody_fraction(lambda_t: f64) -> f64 {
    if lambda_t.is_nan() {
        return f64::NAN;
    }
    if lambda_t <= 0.0 {
        return 0.0;
    }
    if lambda_t == f64::INFINITY {
        return 1.0;
    }
    let pi4 = std::f64::consts::PI.powi(4);
    let xi = C2 / lambda_t;
    if xi >= 2.0 {
        let mut sum = 0.0;
        for n in 1..=40 {
            let nf = n as f64;
            let term = (-nf * xi).exp() / nf * (xi.powi(3) + 3.0 * xi * xi / nf + 6.0 * xi / (nf * nf) + 6.0 / nf.powi(3));
            sum += term;
            if term < 1e-18 * sum {
                break;
            }
        }
        (15.0 / pi4 * sum).clamp(0.0, 1.0)
    } else {
        // ∫₀^ξ x³/(eˣ − 1) dx = Σ_k B_k ξ^{k+3} / (k! (k + 3)), Bernoulli numbers B_k
        // (B₁ = −½; odd ones above 1 vanish); converges for ξ < 2π.
        const B: [(u32, f64); 12] = [
            (0, 1.0),
            (1, -0.5),
            (2, 1.0 / 6.0),
            (4, -1.0 / 30.0),
            (6, 1.0 / 42.0),
            (8, -1.0 / 30.0),
            (10, 5.0 / 66.0),
            (12, -691.0 / 2730.0),
            (14, 7.0 / 6.0),
            (16, -3617.0 / 510.0),
            (18, 43867.0 / 798.0),
            (20, -174611.0 / 330.0),
        ];
        let mut integral = 0.0;
        for &(k, bk) in &B {
            let fact: f64 = (1..=k).map(f64::from).product();
            integral += bk * xi.powi(k as i32 + 3) / (fact * f64::from(k + 3));
        }
        (1.0 - 15.0 / pi4 * integral).clamp(0.0, 1.0)
    }
}

/// The share of a blackbody's emission at `t` kelvin in each band of `edges` (µm): the
/// bands are `[0, λ₁), [λ₁, λ₂), …, [λ_last, ∞)`, so there are `edges.len() + 1`, summing
/// to 1. At 0 K (no emission) every share is 0 but the last, which is 1.
pub fn band_fractions(edges: &[f64], t: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(edges.len() + 1);
    let mut below = 0.0;
    for &e in edges {
        let f = if t > 0.0 { blackbody_fraction(e * t) } else { 0.0 };
        out.push((f - below).max(0.0));
        below = f.max(below);
    }
    out.push(1.0 - below);
    out
}

/// Band edges that make sense: finite, positive, increasing, at most [`MAX_BANDS`] bands.
pub fn check_edges(edges: &[f64]) -> Result<()> {
    if let Some(e) = edges.iter().find(|e| !(e.is_finite() && **e > 0.0)) {
        return Err(Error::Invalid(format!("band edge {e} µm must be a finite, positive wavelength")));
    }
    if let Some(w) = edges.windows(2).find(|w| !(w[1] > w[0])) {
        return Err(Error::Invalid(format!("band edges must increase: {} µm then {} µm", w[0], w[1])));
    }
    if edges.len() + 1 > MAX_BANDS {
        return Err(Error::Invalid(format!("{} bands: at most {MAX_BANDS}", edges.len() + 1)));
    }
    Ok(())
}

/// The error for a material whose per-band emissivities do not match the bands.
pub(crate) fn count_error(material: &str, given: usize, edges: &[f64]) -> Error {
    let bands: Vec<String> = std::iter::once(0.0)
        .chain(edges.iter().copied())
        .zip(edges.iter().map(|e| format!("{e}")).chain(std::iter::once("∞".to_string())))
        .map(|(lo, hi)| format!("{lo}–{hi} µm"))
        .collect();
    if edges.is_empty() {
        Error::Invalid(format!(
            "material '{material}' gives {given} band emissivities but the solve has no band edges: give [thermal] \
             band_edges in the scene or --bands"
        ))
    } else {
        Error::Invalid(format!(
            "material '{material}' gives {given} band emissivities for {} band(s) ({})",
            edges.len() + 1,
            bands.join(", ")
        ))
    }
}

/// Largest number of substitution steps for the temperatures of flux surfaces.
const MAX_ITERATIONS: usize = 200;

/// Solves the banded exchange (see the module docs) on the view factors `f` (with `f_env`,
/// what each row leaves to the environment at `t_env` kelvin).
pub(crate) fn solve(f: &DenseMatrix, spec: &[&ThermalSpec], f_env: &[f64], edges: &[f64], t_env: f64) -> Result<ElementSolution> {
    let sigma = STEFAN_BOLTZMANN;
    let n = spec.len();
    let nb = edges.len() + 1;
    let eps = |r: usize, b: usize| {
        let s = spec[r];
        if s.band_emissivity.is_empty() {
            s.emissivity
        } else {
            s.band_emissivity[b]
        }
    };
    let env = sigma * t_env.powi(4);
    let env_share = band_fractions(edges, t_env);
    let given: Vec<Option<(f64, Vec<f64>)>> = spec
        .iter()
        .map(|s| match s.boundary {
            Boundary::Temperature(t) => Some((sigma * t.powi(4), band_fractions(edges, t))),
            _ => None,
        })
        .collect();
    // Flux and adiabatic elements: the unknown σT⁴.
    let unknown: Vec<usize> = (0..n).filter(|&r| given[r].is_none()).collect();
    let nu = unknown.len();
    let f_unknown = Mat::<f64>::from_fn(nu, n, |k, j| f.get(unknown[k], j));
    // Per band: X_b = A_b⁻¹ [r_b | E_b] (n × (1 + nu)): the radiosity from the known
    // emission, and from a unit σT⁴ of each flux element times its ε_b; W_b = the flux
    // elements' rows of (I − F) X_b.
    let mut x = Vec::with_capacity(nb);
    let mut w = Vec::with_capacity(nb);
    for b in 0..nb {
        let a = Mat::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } - (1.0 - eps(i, b)) * f.get(i, j));
        let mut xb = Mat::<f64>::zeros(n, 1 + nu);
        for r in 0..n {
            let e = eps(r, b);
            xb[(r, 0)] = (1.0 - e) * f_env[r] * env_share[b] * env
                + given[r].as_ref().map_or(0.0, |(s, share)| e * share[b] * s);
        }
        for (k, &u) in unknown.iter().enumerate() {
            xb[(u, 1 + k)] = eps(u, b);
        }
        lu_solve_dense(a, &mut xb);
        let fx = &f_unknown * &xb;
        let wb = Mat::<f64>::from_fn(nu, 1 + nu, |k, c| xb[(unknown[k], c)] - fx[(k, c)]);
        x.push(xb);
        w.push(wb);
    }
    // σT⁴ of the flux elements: Σ_b W_b[:, 1 + l] f_b(T_l) s_l = q + F_env σT_env⁴ − Σ_b W_b[:, 0].
    let target: Vec<f64> = unknown
        .iter()
        .enumerate()
        .map(|(k, &u)| {
            let q = match spec[u].boundary {
                Boundary::HeatFlux(q) => q,
                _ => 0.0,
            };
            q + f_env[u] * env - (0..nb).map(|b| w[b][(k, 0)]).sum::<f64>()
        })
        .collect();
    // Start from the mean emission of the given temperatures (or the environment's).
    let known: Vec<f64> = given.iter().flatten().map(|g| g.0).chain((env > 0.0).then_some(env)).collect();
    let start = if known.is_empty() { sigma * 300f64.powi(4) } else { known.iter().sum::<f64>() / known.len() as f64 };
    let mut s = vec![start; nu];
    let mut share: Vec<Vec<f64>> = s.iter().map(|v| band_fractions(edges, (v / sigma).powf(0.25))).collect();
    if nu > 0 {
        let mut converged = false;
        for _ in 0..MAX_ITERATIONS {
            let mut m = Mat::<f64>::from_fn(nu, nu, |k, l| (0..nb).map(|b| w[b][(k, 1 + l)] * share[l][b]).sum());
            let mut rhs = Mat::<f64>::from_fn(nu, 1, |k, _| target[k]);
            lu_solve_dense(std::mem::replace(&mut m, Mat::zeros(0, 0)), &mut rhs);
            let next: Vec<f64> = (0..nu).map(|k| rhs[(k, 0)]).collect();
            if next.iter().any(|v| !v.is_finite()) {
                return Err(singular());
            }
            let temp = |v: f64| (v.max(0.0) / sigma).powf(0.25);
            let change = next.iter().zip(&s).map(|(a, b)| (temp(*a) - temp(*b)).abs()).fold(0.0, f64::max);
            let scale = next.iter().map(|v| temp(*v)).fold(0.0, f64::max);
            s = next;
            share = s.iter().map(|v| band_fractions(edges, temp(*v))).collect();
            if change <= 1e-12 * scale.max(f64::MIN_POSITIVE) {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(Error::Invalid(format!(
                "the temperatures of the heat-flux and adiabatic surfaces did not settle in {MAX_ITERATIONS} band \
                 iterations"
            )));
        }
    }
    // Radiosity per band, then irradiance and net flux.
    let mut out = ElementSolution {
        j: vec![0.0; n],
        g: vec![0.0; n],
        t4: vec![0.0; n],
        eps: vec![0.0; n],
        band_q: vec![vec![0.0; nb]; n],
    };
    for b in 0..nb {
        let xb = &x[b];
        let jb: Vec<f64> = (0..n).map(|r| xb[(r, 0)] + (0..nu).map(|k| xb[(r, 1 + k)] * share[k][b] * s[k]).sum::<f64>()).collect();
        for r in 0..n {
            let gb = f.row(r).iter().zip(&jb).map(|(fv, jv)| fv * jv).sum::<f64>() + f_env[r] * env_share[b] * env;
            out.j[r] += jb[r];
            out.g[r] += gb;
            out.band_q[r][b] = jb[r] - gb;
        }
    }
    let mut slot = vec![usize::MAX; n];
    for (k, &u) in unknown.iter().enumerate() {
        slot[u] = k;
    }
    for r in 0..n {
        let (e4, sh) = match &given[r] {
            Some((e4, sh)) => (*e4, sh.as_slice()),
            None => (s[slot[r]].max(0.0), share[slot[r]].as_slice()),
        };
        out.t4[r] = e4 / sigma;
        out.eps[r] = (0..nb).map(|b| eps(r, b) * sh[b]).sum();
    }
    if out.j.iter().chain(&out.g).any(|v| !v.is_finite()) {
        return Err(singular());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `F(λT)` by quadrature of Planck's law (Simpson on x = C₂/λT, 20 000 panels).
    fn by_quadrature(lambda_t: f64) -> f64 {
        let xi = C2 / lambda_t;
        let (a, b, n) = (xi, xi + 60.0, 20_000);
        let h = (b - a) / n as f64;
        let g = |x: f64| x.powi(3) / x.exp_m1();
        let mut s = g(a) + g(b);
        for k in 1..n {
            s += g(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        15.0 / std::f64::consts::PI.powi(4) * s * h / 3.0
    }

    #[test]
    fn blackbody_fraction_matches_planck_and_the_tables() {
        // Both series against the integral of Planck's law, across the switch at ξ = 2.
        for lt in [300.0, 1000.0, 2000.0, 2897.8, 5000.0, 7000.0, 7200.0, 7300.0, 10_000.0, 30_000.0, 1e6] {
            let (a, b) = (blackbody_fraction(lt), by_quadrature(lt));
            assert!((a - b).abs() <= 1e-10, "λT {lt}: {a} vs quadrature {b}");
        }
        // Modest, Table C.5 (λT in µm·K).
        for (lt, v) in [(1000.0, 0.000321), (2000.0, 0.06672), (3000.0, 0.27323), (5000.0, 0.63372), (10_000.0, 0.91416)] {
            assert!((blackbody_fraction(lt) - v).abs() <= 2e-5, "λT {lt}: {} vs {v}", blackbody_fraction(lt));
        }
        assert_eq!(blackbody_fraction(0.0), 0.0);
        assert_eq!(blackbody_fraction(f64::INFINITY), 1.0);
    }

    #[test]
    fn band_shares_sum_to_one() {
        let edges = [2.0, 4.0, 10.0];
        for t in [0.0, 300.0, 1000.0, 5800.0] {
            let f = band_fractions(&edges, t);
            assert_eq!(f.len(), 4);
            assert!((f.iter().sum::<f64>() - 1.0).abs() <= 1e-14, "{f:?}");
            assert!(f.iter().all(|v| *v >= 0.0));
        }
        // The sun (5 800 K) puts most of its emission below 4 µm, a room (300 K) above.
        assert!(band_fractions(&[4.0], 5800.0)[0] > 0.98);
        assert!(band_fractions(&[4.0], 300.0)[1] > 0.99);
    }

    #[test]
    fn bad_edges_are_refused() {
        assert!(check_edges(&[4.0, 2.0]).unwrap_err().to_string().contains("must increase"));
        assert!(check_edges(&[0.0]).is_err());
        assert!(check_edges(&[f64::NAN]).is_err());
        assert!(check_edges(&[1.0, 3.0]).is_ok());
    }
}
