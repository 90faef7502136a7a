//! A dense `n × n` matrix of f64, row-major, for view-factor matrices that users want in
//! full (thermal work): allocated only after checking that it fits in memory.

use crate::{Error, Result};

/// A dense square matrix of f64.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseMatrix {
    n: usize,
    data: Vec<f64>,
}

impl DenseMatrix {
    /// Bytes an `n × n` matrix needs.
    pub fn bytes_for(n: usize) -> u64 {
        (n as u64) * (n as u64) * 8
    }

    /// A zero matrix, or [`Error::TooLarge`] naming the size when it would not fit in
    /// `limit` bytes (None: the memory the system reports available; unknown: no check).
    pub fn zeros(n: usize, limit: Option<u64>, what: &str) -> Result<Self> {
        let needed = Self::bytes_for(n);
        if let Some(limit) = limit.or_else(available_memory) {
            if needed > limit {
                return Err(Error::TooLarge {
                    what: format!("{what} ({n} × {n}, f64)"),
                    needed,
                    limit,
                    hint: "compute it per object, with a larger mesh size, or stream it to a file without --enclosure"
                        .into(),
                });
            }
        }
        let len = usize::try_from(needed / 8).map_err(|_| Error::Invalid(format!("{n} × {n} is too large")))?;
        Ok(DenseMatrix { n, data: vec![0.0; len] })
    }

    /// From row-major values.
    pub fn from_rows(n: usize, data: Vec<f64>) -> Self {
        assert_eq!(data.len(), n * n);
        DenseMatrix { n, data }
    }

    /// The row-major values, without a copy.
    pub fn into_vec(self) -> Vec<f64> {
        self.data
    }

    /// Number of rows (= columns).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Row `i`.
    #[inline]
    pub fn row(&self, i: usize) -> &[f64] {
        &self.data[i * self.n..(i + 1) * self.n]
    }

    /// Row `i`, mutable.
    #[inline]
    pub fn row_mut(&mut self, i: usize) -> &mut [f64] {
        &mut self.data[i * self.n..(i + 1) * self.n]
    }

    /// Entry `(i, j)`.
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.data[i * self.n + j]
    }

    /// Sets entry `(i, j)`.
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, v: f64) {
        self.data[i * self.n + j] = v;
    }

    /// All values, row-major.
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }

    /// All values, row-major, mutable.
    pub fn as_mut_slice(&mut self) -> &mut [f64] {
        &mut self.data
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.data.len() * 8
    }
}

/// Memory available to this process in bytes: `MemAvailable` from `/proc/meminfo` (Linux),
/// None elsewhere or when it cannot be read.
pub fn available_memory() -> Option<u64> {
    proc_kb("/proc/meminfo", "MemAvailable:")
}

/// Resident memory of this process in bytes: `VmRSS` from `/proc/self/status` (Linux), None
/// elsewhere or when it cannot be read. What a run holds already when it predicts its peak.
pub fn resident_memory() -> Option<u64> {
    proc_kb("/proc/self/status", "VmRSS:")
}

/// The value of the line starting with `key` in the `/proc` file `path`, in kB, as bytes.
fn proc_kb(path: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(path).ok()?;
    let rest = text.lines().find_map(|l| l.strip_prefix(key))?;
    let kb: u64 = rest.trim().trim_end_matches("kB").trim().parse().ok()?;
    kb.checked_mul(1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_large_names_the_size() {
        let e = DenseMatrix::zeros(100_000, Some(1 << 30), "the view-factor matrix").unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("74.5 GiB") && msg.contains("1.0 GiB"), "{msg}");
        let m = DenseMatrix::zeros(3, Some(1 << 30), "m").unwrap();
        assert_eq!(m.row(2), &[0.0; 3]);
    }
}
