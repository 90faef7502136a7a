//! Enclosure correction: the nearest matrix with exact reciprocity and closure.
//!
//! ```text
//! find F' with   A_i F'_ij = A_j F'_ji,   Σ_j F'_ij = 1,   F'_ij ≥ 0,   F'_ij = 0 where F_ij = F_ji = 0
//! ```
//!
//! The symmetric part `G_ij = (A_i F_ij + A_j F_ji) / 2` (exchange areas: reciprocity made
//! exact by averaging) is scaled symmetrically, `A_i F'_ij = d_i G_ij d_j`, with the
//! positive vector `d` chosen so that every row closes, `d_i Σ_j G_ij d_j = A_i`. That is a
//! symmetric matrix-balancing problem, solved by the symmetric Sinkhorn–Knopp iteration
//! `d ← √(d ∘ A / (G d))` (Knight 2008, "The Sinkhorn–Knopp algorithm: convergence and
//! applications"). Being multiplicative it keeps every factor non-negative and every zero
//! a zero (surfaces that cannot see each other stay so) — which a least-squares
//! adjustment (Lawson 1995; Taylor & Luck 1995) does not guarantee — and for a matrix that
//! is already nearly closed it moves each factor by about its row's closure error. View3D's
//! `NormAF` similarly alternates reciprocity and row normalisation.
//!
//! `G` is never stored: each iteration computes `G d = ½ A ∘ (F d) + ½ Fᵀ (A ∘ d)` from the
//! unchanged `F`, so the correction needs no second copy of the matrix; the final update
//! works on the pairs `(i, j), (j, i)` in place.
//!
//! Only for closed geometry: a row summing to less than 0.9 (energy escapes through an
//! opening) is an error rather than something to force closed.

use rayon::prelude::*;

use crate::transport::DenseMatrix;
use crate::{Error, Result};

/// How far the correction moved the matrix, and what it achieved.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct EnclosureReport {
    /// Balancing iterations.
    pub iterations: usize,
    /// `max_i |1 − Σ_j F_ij|` before.
    pub closure_error_before: f64,
    /// ... and after.
    pub closure_error_after: f64,
    /// Largest relative reciprocity error before (see [`super::diagnostics`]).
    pub reciprocity_rel_before: f64,
    /// ... and after.
    pub reciprocity_rel_after: f64,
    /// `max |F'_ij − F_ij|`.
    pub max_change: f64,
    /// `‖F' − F‖ / ‖F‖` (Frobenius norms).
    pub relative_change: f64,
    /// Negative entries that were set to zero first.
    pub negatives_zeroed: u64,
}

/// Largest row-sum deviation from 1 that is still taken for a (noisy) enclosure.
pub const MAX_CLOSURE_DEVIATION: f64 = 0.1;

/// Replaces `m` (view factors, rows and columns indexed like `areas`) by the nearest
/// reciprocal, closed matrix in the sense above.
pub fn enforce(m: &mut DenseMatrix, areas: &[f64]) -> Result<EnclosureReport> {
    let n = m.n();
    assert_eq!(areas.len(), n);
    let mut rep = EnclosureReport::default();
    // Non-physical negatives (rounding) are zeroed before balancing.
    for v in m.as_mut_slice().iter_mut() {
        if *v < 0.0 {
            *v = 0.0;
            rep.negatives_zeroed += 1;
        }
    }
    let before = super::diagnostics::Diagnostics::of_dense(m, areas, None);
    rep.closure_error_before = before.closure_max_error;
    rep.reciprocity_rel_before = before.reciprocity_max_rel.unwrap_or(0.0);
    for i in 0..n {
        let s: f64 = m.row(i).iter().sum();
        if !(s >= 1.0 - MAX_CLOSURE_DEVIATION && s <= 1.0 + MAX_CLOSURE_DEVIATION) {
            return Err(Error::Invalid(format!(
                "row {i} of the view factors sums to {s:.4}: the geometry is not an enclosure \
                 (energy escapes or the surfaces are oriented the wrong way), so closure cannot be enforced"
            )));
        }
    }
    // Balance: d_i (G d)_i = A_i.
    let mut d = vec![1.0f64; n];
    let gd = |d: &[f64]| -> Vec<f64> {
        let ad: Vec<f64> = areas.iter().zip(d).map(|(a, x)| a * x).collect();
        // F d (rows) and Fᵀ (A∘d) (accumulated per thread, then summed).
        let fd: Vec<f64> = (0..n).into_par_iter().map(|i| m.row(i).iter().zip(d).map(|(f, x)| f * x).sum()).collect();
        let ftad = (0..n)
            .into_par_iter()
            .fold(
                || vec![0.0f64; n],
                |mut acc, i| {
                    let w = ad[i];
                    if w != 0.0 {
                        for (a, f) in acc.iter_mut().zip(m.row(i)) {
                            *a += f * w;
                        }
                    }
                    acc
                },
            )
            .reduce(
                || vec![0.0f64; n],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(&b) {
                        *x += y;
                    }
                    a
                },
            );
        (0..n).map(|i| 0.5 * areas[i] * fd[i] + 0.5 * ftad[i]).collect()
    };
    const MAX_ITER: usize = 2000;
    let mut it = 0;
    loop {
        let y = gd(&d);
        let mut worst: f64 = 0.0;
        for i in 0..n {
            if !(y[i] > 0.0) {
                return Err(Error::Invalid(format!("surface {i} sees no other surface: closure cannot be enforced")));
            }
            worst = worst.max((d[i] * y[i] - areas[i]).abs() / areas[i]);
        }
        if worst <= 1e-14 || it >= MAX_ITER {
            break;
        }
        for i in 0..n {
            d[i] = (d[i] * areas[i] / y[i]).sqrt();
        }
        it += 1;
    }
    rep.iterations = it;
    // F'_ij = d_i d_j G_ij / A_i, pair by pair in place.
    let (mut max_change, mut num, mut den) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..n {
        let old = m.get(i, i);
        let new = d[i] * d[i] * old;
        m.set(i, i, new);
        max_change = max_change.max((new - old).abs());
        num += (new - old) * (new - old);
        den += old * old;
        for j in i + 1..n {
            let (fij, fji) = (m.get(i, j), m.get(j, i));
            let g = 0.5 * (areas[i] * fij + areas[j] * fji) * d[i] * d[j];
            let (nij, nji) = (g / areas[i], g / areas[j]);
            m.set(i, j, nij);
            m.set(j, i, nji);
            for (o, w) in [(fij, nij), (fji, nji)] {
                max_change = max_change.max((w - o).abs());
                num += (w - o) * (w - o);
                den += o * o;
            }
        }
    }
    rep.max_change = max_change;
    rep.relative_change = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
    let after = super::diagnostics::Diagnostics::of_dense(m, areas, None);
    rep.closure_error_after = after.closure_max_error;
    rep.reciprocity_rel_after = after.reciprocity_max_rel.unwrap_or(0.0);
    Ok(rep)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_noisy_cube_matrix_becomes_reciprocal_and_closed() {
        // Unit cube: opposite 0.1998..., adjacent 0.2000...; add deterministic noise.
        let (opp, adj) = (0.199824896, 0.200043776);
        let n = 6;
        let mut v = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                if i != j {
                    let base = if i / 2 == j / 2 { opp } else { adj };
                    let noise = ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.5;
                    v[i * n + j] = base * (1.0 + 0.02 * noise);
                }
            }
        }
        let mut m = DenseMatrix::from_rows(n, v);
        let areas = vec![1.0; 6];
        let rep = enforce(&mut m, &areas).unwrap();
        assert!(rep.closure_error_after < 1e-13, "{rep:?}");
        assert!(rep.reciprocity_rel_after < 1e-13, "{rep:?}");
        assert!(rep.max_change < 0.01 && rep.max_change > 0.0, "{rep:?}");
        assert_eq!(m.get(0, 0), 0.0);
    }

    #[test]
    fn an_open_geometry_is_refused() {
        let mut m = DenseMatrix::from_rows(2, vec![0.0, 0.5, 0.5, 0.0]);
        assert!(enforce(&mut m, &[1.0, 1.0]).is_err());
    }
}
