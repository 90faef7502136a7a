//! Diagnostics of a view-factor matrix: how far it is from what physics requires.
//!
//! ```text
//! reciprocity   A_i F_ij = A_j F_ji
//! closure       Σ_j F_ij = 1 in an enclosure (≤ 1 where energy can escape)
//! range         0 ≤ F_ij ≤ 1
//! ```
//!
//! (e.g. Modest, *Radiative Heat Transfer*, ch. 4.) The reciprocity error is reported in
//! area units, `max |A_i F_ij − A_j F_ji|`, and relative to the larger of the two products;
//! closure as `max_i |1 − Σ_j F_ij|` together with the smallest and largest row sums (for
//! an open scene only the largest, which must stay ≤ 1, is meaningful).

use rayon::prelude::*;

use crate::transport::DenseMatrix;

/// What is wrong with a matrix, in numbers.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Diagnostics {
    /// Number of rows.
    pub n: usize,
    /// `max |A_i F_ij − A_j F_ji|` in area units (None when the matrix was streamed and
    /// not held).
    pub reciprocity_max_abs: Option<f64>,
    /// `max |A_i F_ij − A_j F_ji| / max(A_i F_ij, A_j F_ji)` over pairs with a non-zero
    /// product.
    pub reciprocity_max_rel: Option<f64>,
    /// The pair with the largest relative reciprocity error.
    pub reciprocity_worst_pair: Option<[usize; 2]>,
    /// Smallest row sum `Σ_j F_ij`.
    pub row_sum_min: f64,
    /// Largest row sum.
    pub row_sum_max: f64,
    /// `max_i |1 − Σ_j F_ij|` (the enclosure error; meaningful for closed geometry).
    pub closure_max_error: f64,
    /// The row with the largest closure error.
    pub closure_worst_row: usize,
    /// Entries below zero.
    pub negative_entries: u64,
    /// Smallest entry.
    pub min_entry: f64,
    /// Entries above one.
    pub entries_above_one: u64,
    /// Largest entry.
    pub max_entry: f64,
}

/// Accumulates the row-wise diagnostics (everything but reciprocity) one row at a time,
/// for matrices streamed to a file.
#[derive(Clone, Debug)]
pub struct RowDiagnostics {
    d: Diagnostics,
}

impl Default for RowDiagnostics {
    fn default() -> Self {
        RowDiagnostics {
            d: Diagnostics {
                row_sum_min: f64::INFINITY,
                row_sum_max: f64::NEG_INFINITY,
                min_entry: f64::INFINITY,
                max_entry: f64::NEG_INFINITY,
                ..Default::default()
            },
        }
    }
}

impl RowDiagnostics {
    /// Adds row number `i`.
    pub fn add_row(&mut self, i: usize, row: &[f64]) {
        let d = &mut self.d;
        d.n += 1;
        let mut sum = 0.0;
        for &v in row {
            sum += v;
            if v < 0.0 {
                d.negative_entries += 1;
            }
            if v > 1.0 {
                d.entries_above_one += 1;
            }
            d.min_entry = d.min_entry.min(v);
            d.max_entry = d.max_entry.max(v);
        }
        d.row_sum_min = d.row_sum_min.min(sum);
        d.row_sum_max = d.row_sum_max.max(sum);
        let e = (1.0 - sum).abs();
        if e > d.closure_max_error || d.n == 1 {
            d.closure_max_error = e;
            d.closure_worst_row = i;
        }
    }

    /// The diagnostics so far.
    pub fn finish(self) -> Diagnostics {
        let mut d = self.d;
        if d.n == 0 {
            d = Diagnostics::default();
        }
        d
    }
}

impl Diagnostics {
    /// All diagnostics of the sub-matrix of `m` on the rows and columns `index` (all when
    /// None), with `areas` indexed like `m`.
    pub fn of_dense(m: &DenseMatrix, areas: &[f64], index: Option<&[usize]>) -> Diagnostics {
        let all: Vec<usize>;
        let index = match index {
            Some(ix) => ix,
            None => {
                all = (0..m.n()).collect();
                &all
            }
        };
        let mut rows = RowDiagnostics::default();
        let mut buf = Vec::with_capacity(index.len());
        for (r, &i) in index.iter().enumerate() {
            buf.clear();
            buf.extend(index.iter().map(|&j| m.get(i, j)));
            rows.add_row(r, &buf);
        }
        let mut d = rows.finish();
        // Pairs (a, b), a < b, in 64 × 64 tiles so that both m[i][j] and m[j][i] stream
        // through the cache; tiles in parallel.
        const T: usize = 64;
        let k = index.len();
        let tiles: Vec<(usize, usize)> =
            (0..k).step_by(T).flat_map(|a0| (a0..k).step_by(T).map(move |b0| (a0, b0))).collect();
        let (abs, rel, worst) = tiles
            .par_iter()
            .map(|&(a0, b0)| {
                let (mut abs, mut rel, mut worst) = (0.0f64, 0.0f64, None);
                for a in a0..(a0 + T).min(k) {
                    let i = index[a];
                    for b in b0.max(a + 1)..(b0 + T).min(k) {
                        let j = index[b];
                        let x = areas[i] * m.get(i, j);
                        let y = areas[j] * m.get(j, i);
                        let e = (x - y).abs();
                        abs = abs.max(e);
                        let big = x.abs().max(y.abs());
                        if big > 0.0 && e / big > rel {
                            rel = e / big;
                            worst = Some([a, b]);
                        }
                    }
                }
                (abs, rel, worst)
            })
            .reduce(
                || (0.0, 0.0, None),
                |p, q| {
                    let abs = p.0.max(q.0);
                    if q.1 > p.1 || (q.1 == p.1 && q.2 < p.2 && q.2.is_some()) {
                        (abs, q.1, q.2)
                    } else {
                        (abs, p.1, p.2)
                    }
                },
            );
        d.reciprocity_max_abs = Some(abs);
        d.reciprocity_max_rel = Some(rel);
        d.reciprocity_worst_pair = worst;
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reciprocity_and_closure_of_a_small_matrix() {
        // Two surfaces of areas 1 and 2; A1 F12 = 0.5 but A2 F21 = 0.6.
        let m = DenseMatrix::from_rows(2, vec![0.0, 0.5, 0.3, 0.0]);
        let d = Diagnostics::of_dense(&m, &[1.0, 2.0], None);
        assert!((d.reciprocity_max_abs.unwrap() - 0.1).abs() < 1e-15);
        assert!((d.reciprocity_max_rel.unwrap() - 0.1 / 0.6).abs() < 1e-15);
        assert_eq!(d.closure_worst_row, 1);
        assert!((d.closure_max_error - 0.7).abs() < 1e-15);
        assert_eq!(d.negative_entries, 0);
    }
}
