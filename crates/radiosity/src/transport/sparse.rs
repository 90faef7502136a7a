//! Compressed sparse rows of form factors (f32 values, u32 column indices).

use rayon::prelude::*;

use super::Transport;
use crate::Rgb;

/// Form factors stored by rows: entries `(j, F_ij)` with `F_ij > 0`, columns ascending.
#[derive(Clone, Debug, Default)]
pub struct SparseRows {
    n: usize,
    row_start: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f32>,
}

impl SparseRows {
    /// Assembles from per-row entry lists (each sorted by column).
    pub fn from_rows(rows: Vec<Vec<(u32, f32)>>) -> Self {
        let n = rows.len();
        let nnz: usize = rows.iter().map(Vec::len).sum();
        let mut row_start = Vec::with_capacity(n + 1);
        let mut cols = Vec::with_capacity(nnz);
        let mut vals = Vec::with_capacity(nnz);
        row_start.push(0);
        for r in rows {
            for (j, v) in r {
                cols.push(j);
                vals.push(v);
            }
            row_start.push(cols.len());
        }
        SparseRows { n, row_start, cols, vals }
    }

    /// Number of rows (= columns).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.vals.len()
    }

    /// Row `i`: column indices and values.
    #[inline]
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        let (a, b) = (self.row_start[i], self.row_start[i + 1]);
        (&self.cols[a..b], &self.vals[a..b])
    }

    /// `F_ij` (zero if not stored).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (c, v) = self.row(i);
        match c.binary_search(&(j as u32)) {
            Ok(k) => v[k] as f64,
            Err(_) => 0.0,
        }
    }

    /// `Σ_j F_ij`.
    pub fn row_sum(&self, i: usize) -> f64 {
        self.row(i).1.iter().map(|&v| v as f64).sum()
    }

    /// `Σ_j F_ij x_j` for one row.
    #[inline]
    pub fn gather_row(&self, i: usize, x: &[Rgb]) -> Rgb {
        let (c, v) = self.row(i);
        let mut acc = Rgb::ZERO;
        for (&j, &f) in c.iter().zip(v) {
            acc += x[j as usize] * f as f64;
        }
        acc
    }

    /// The transpose (rows become columns), for shooting.
    pub fn transpose(&self) -> SparseRows {
        let mut count = vec![0usize; self.n + 1];
        for &j in &self.cols {
            count[j as usize + 1] += 1;
        }
        for k in 0..self.n {
            count[k + 1] += count[k];
        }
        let row_start = count.clone();
        let mut fill = count;
        let mut cols = vec![0u32; self.nnz()];
        let mut vals = vec![0f32; self.nnz()];
        for i in 0..self.n {
            let (c, v) = self.row(i);
            for (&j, &f) in c.iter().zip(v) {
                let p = fill[j as usize];
                cols[p] = i as u32;
                vals[p] = f;
                fill[j as usize] += 1;
            }
        }
        SparseRows { n: self.n, row_start, cols, vals }
    }
}

impl Transport for SparseRows {
    fn len(&self) -> usize {
        self.n
    }
    fn gather(&self, x: &[Rgb], y: &mut [Rgb]) {
        y.par_iter_mut().enumerate().with_min_len(64).for_each(|(i, yi)| *yi = self.gather_row(i, x));
    }
    fn rows(&self) -> Option<&SparseRows> {
        Some(self)
    }
    fn memory_bytes(&self) -> usize {
        self.row_start.len() * 8 + self.cols.len() * 4 + self.vals.len() * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transpose_and_gather() {
        let m = SparseRows::from_rows(vec![vec![(1, 0.5), (2, 0.25)], vec![(0, 1.0)], vec![]]);
        let t = m.transpose();
        assert_eq!(t.get(1, 0), 0.5);
        assert_eq!(t.get(2, 0), 0.25);
        assert_eq!(t.get(0, 1), 1.0);
        let x = vec![Rgb::splat(1.0), Rgb::splat(2.0), Rgb::splat(4.0)];
        let mut y = vec![Rgb::ZERO; 3];
        m.gather(&x, &mut y);
        assert_eq!(y[0], Rgb::splat(2.0));
        assert_eq!(y[1], Rgb::splat(1.0));
        assert_eq!(y[2], Rgb::ZERO);
    }
}
