//! Stage 4b: the transport operator — what the solvers multiply by.
//!
//! The radiosity system is `B = E + ρ·F·B`, with `F[i][j]` the fraction of the energy
//! leaving element `i` that arrives at element `j` ... read as a gather: element `i`
//! receives `Σ_j F_ij B_j` (Cohen & Wallace 1993, eq. 2.5). Solvers only need the product
//! `y = F·x` ([`Transport::gather`]); some (Gauss–Seidel, shooting) also need single rows or
//! columns, which [`SparseRows`] provides. Hierarchical links (Hanrahan et al. 1991) and
//! ray-based matrix-free operators implement the same trait, so no solver assumes an
//! `n × n` matrix.

mod dense;
mod sparse;

pub use dense::{available_memory, DenseMatrix};
pub use sparse::SparseRows;

use crate::Rgb;

/// A linear operator `y = F·x` over per-element RGB values.
pub trait Transport: Sync {
    /// Number of elements.
    fn len(&self) -> usize;
    /// True when there are no elements.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// `y[i] = Σ_j F_ij · x[j]` for every `i`.
    fn gather(&self, x: &[Rgb], y: &mut [Rgb]);
    /// The explicit rows, when the operator stores them.
    fn rows(&self) -> Option<&SparseRows> {
        None
    }
    /// Bytes of memory held.
    fn memory_bytes(&self) -> usize;
}
