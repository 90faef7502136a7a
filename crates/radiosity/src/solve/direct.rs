//! Direct solution `B = (I − ρF)⁻¹ E` by LU factorisation with partial pivoting (faer),
//! one dense factorisation per distinct reflectance channel (grey scenes factor once and
//! solve the three channels together).
//!
//! The reference the iterative solvers are checked against (Goral, Torrance, Greenberg &
//! Battaile 1984 solved the system this way). It needs the dense `n × n` matrix — 8·n²
//! bytes — and O(n³) time, so it refuses systems above [`Options::direct_memory_limit`]
//! (2 GiB by default, 16 384 elements) with [`Error::TooLarge`] naming the memory it
//! would need and the iterative solvers to use instead. The factorisation itself cannot be
//! interrupted; an interrupt is honoured between channels (unsolved channels then keep
//! B = E, and the residual says so).
//!
//! [`Options::direct_memory_limit`]: super::Options::direct_memory_limit

use std::borrow::Cow;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve as lu_solve};
use faer::{Mat, Par};

use super::{energy_gathering, Monitor, Solution, Solver, StopReason, System};
use crate::{Error, Result, Rgb};

/// Bytes the direct solve of `n` elements allocates (the dense matrix dominates).
pub fn memory_bytes(n: usize) -> u64 {
    let n = n as u64;
    8 * n * n + 64 * n
}

/// Refuses the direct solve of `n` elements when it needs more than `limit` bytes, with
/// the error the solve itself gives; the pipeline calls it right after meshing, before any
/// form factor is computed.
pub fn check_memory(n: usize, limit: u64) -> Result<()> {
    let needed = memory_bytes(n);
    if needed > limit {
        return Err(Error::TooLarge {
            what: format!("the direct solve of {n} elements (a dense {n}×{n} matrix)"),
            needed,
            limit,
            hint: "use --solver gauss-seidel or --solver progressive, which need only the form factors".into(),
        });
    }
    Ok(())
}

pub(super) fn solve(sys: &System, mon: &mut Monitor) -> Result<Solution> {
    let rows = sys.rows(Solver::Direct)?;
    let n = sys.len();
    check_memory(n, mon.opts.direct_memory_limit)?;
    // Channels with identical reflectance share one factorisation.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for c in 0..3 {
        match groups.iter_mut().find(|g| sys.reflectance.iter().all(|r| r[g[0]] == r[c])) {
            Some(g) => g.push(c),
            None => groups.push(vec![c]),
        }
    }
    let par = Par::rayon(0);
    let mut b: Vec<Rgb> = sys.emission.to_vec();
    let mut stop = StopReason::Converged;
    let mut a = Mat::<f64>::zeros(n, n);
    let mut perm = vec![0usize; n];
    let mut perm_inv = vec![0usize; n];
    let scratch = factor::lu_in_place_scratch::<usize, f64>(n, n, par, Default::default())
        .or(lu_solve::solve_in_place_scratch::<usize, f64>(n, 3, par));
    let mut mem = MemBuffer::new(scratch);
    for group in &groups {
        if let Some(s) = mon.interrupted() {
            stop = s;
            break;
        }
        let c0 = group[0];
        // A = I − diag(ρ_c) F, column-major.
        a.fill(0.0);
        for i in 0..n {
            a[(i, i)] = 1.0;
            let rho = sys.reflectance[i][c0];
            let (cols, vals) = rows.row(i);
            for (&j, &f) in cols.iter().zip(vals) {
                a[(i, j as usize)] -= rho * f as f64;
            }
        }
        let (_, p) = factor::lu_in_place(a.as_mut(), &mut perm, &mut perm_inv, par, MemStack::new(&mut mem), Default::default());
        let mut rhs = Mat::<f64>::from_fn(n, group.len(), |i, k| sys.emission[i][group[k]]);
        lu_solve::solve_in_place(a.as_ref(), a.as_ref(), p, rhs.as_mut(), par, MemStack::new(&mut mem));
        for i in 0..n {
            for (k, &c) in group.iter().enumerate() {
                b[i][c] = rhs[(i, k)];
            }
        }
    }
    drop(a);
    let residual = sys.residual(&b);
    mon.watch(residual, Some(&b))?;
    mon.record(1, 1.0, residual);
    mon.observe(1, residual, || Cow::Borrowed(&b));
    let energy = energy_gathering(sys, &b, None);
    Ok(Solution { radiosity: b, ambient: None, energy, stats: mon.finish(1, residual, stop, None) })
}
