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
pub mod hierarchical;
mod sparse;

pub use dense::{available_memory, resident_memory, DenseMatrix};
pub use hierarchical::Hierarchy;
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
    /// Frees scratch memory kept from one product to the next (the hierarchy's per-node
    /// buffers), once no more products follow soon.
    fn release_buffers(&self) {}
}

/// How the operator is represented: a runtime choice (`--transport`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// One row of form factors per element ([`SparseRows`]): O(n²) time and memory, every
    /// solver.
    #[default]
    Rows,
    /// Links between nodes of an element tree with clusters ([`Hierarchy`]): O(n log n);
    /// the solvers that only multiply by F (Jacobi) and the stochastic ones.
    Hierarchical,
    /// Hierarchical from [`AUTO_PATCHES`] input polygons or above [`AUTO_ELEMENTS`]
    /// elements when the solver and form-factor method allow it, else rows.
    Auto,
}

/// Elements above which [`Kind::Auto`] picks the hierarchical operator whatever the scene:
/// at 50 000 elements rows would take minutes and gigabytes (n²), the hierarchy about 30 s
/// (BENCHMARKS.md).
pub const AUTO_ELEMENTS: u64 = 50_000;

/// Input polygons from which [`Kind::Auto`] picks the hierarchical operator at any element
/// count: a furnished room, whose many small polygons the hierarchy links as clusters.
/// Measured 2026-12-06 (BENCHMARKS.md, "Tenth round"), default mesh, per-object median
/// error against the path tracer and 256² light-masked image error, hierarchical (indirect
/// interpolated, [`crate::pipeline::Solved::default_gather_axis`]) against rows:
/// the classroom (5 826 polygons, 12 230 elements) 2.35 % / 5.50 % against 3.32 % / 5.75 %,
/// default render 9.6 s against 16.0 s; office2 (438 polygons, 4 757 elements; medians
/// over seeds 0–4) 1.98 % / 4.08 % against 1.86 % / 4.28 %, 2.1 s against 3.1 s; with 64
/// closure rays per element ("Eleventh round") office2's median over seeds 0–7 is 1.63 %
/// against 1.71 % for rows, the classroom's 2.29 %. A box of a few large walls cut into
/// many elements keeps rows, which are exact per element there: the Cornell box (20
/// polygons, 5 144 elements) is 1.99 % hierarchical against 1.63 % with rows (issue 5
/// asks ≤ 2 %).
pub const AUTO_PATCHES: u64 = 256;

impl Kind {
    /// Every kind.
    pub const ALL: [Kind; 3] = [Kind::Rows, Kind::Hierarchical, Kind::Auto];
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Rows => "rows",
            Kind::Hierarchical => "hierarchical",
            Kind::Auto => "auto",
        }
    }
}

impl std::fmt::Display for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Kind {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        Kind::ALL.iter().copied().find(|k| k.name() == s).ok_or_else(|| {
            crate::Error::Invalid(format!("unknown transport '{s}' (known: rows, hierarchical, auto)"))
        })
    }
}

/// The operator a solve runs on: explicit rows or hierarchical links.
#[derive(Clone, Debug)]
pub enum Operator {
    /// Form-factor rows.
    Rows(SparseRows),
    /// Hierarchical links.
    Hierarchical(Hierarchy),
}

impl Operator {
    /// The hierarchy, when the operator is one.
    pub fn hierarchy(&self) -> Option<&Hierarchy> {
        match self {
            Operator::Hierarchical(h) => Some(h),
            Operator::Rows(_) => None,
        }
    }
    /// `Σ_j F_ij` of every element.
    pub fn row_sums(&self) -> Vec<f64> {
        match self {
            Operator::Rows(r) => (0..r.n()).map(|i| r.row_sum(i)).collect(),
            Operator::Hierarchical(h) => h.row_sums(),
        }
    }
}

impl Transport for Operator {
    fn len(&self) -> usize {
        match self {
            Operator::Rows(r) => r.len(),
            Operator::Hierarchical(h) => h.len(),
        }
    }
    fn gather(&self, x: &[Rgb], y: &mut [Rgb]) {
        match self {
            Operator::Rows(r) => r.gather(x, y),
            Operator::Hierarchical(h) => h.gather(x, y),
        }
    }
    fn rows(&self) -> Option<&SparseRows> {
        match self {
            Operator::Rows(r) => Some(r),
            Operator::Hierarchical(_) => None,
        }
    }
    fn memory_bytes(&self) -> usize {
        match self {
            Operator::Rows(r) => r.memory_bytes(),
            Operator::Hierarchical(h) => h.memory_bytes(),
        }
    }
    fn release_buffers(&self) {
        if let Operator::Hierarchical(h) = self {
            h.release_buffers();
        }
    }
}
