//! Stage 5: solving `B = E + ρ·F·B` for the radiosity `B` of every element, per RGB channel.
//!
//! Every solver is a runtime choice ([`Solver`]), one file per method, and each reports its
//! convergence after every iteration, stops on a tolerance, an iteration cap, a time budget
//! or an interrupt ([`Progress::should_stop`]) and keeps the best solution so far:
//!
//! | name | file | iteration | paper |
//! |---|---|---|---|
//! | `direct` | `direct.rs` | LU of `I − ρF` (dense, faer) | — |
//! | `jacobi` | `jacobi.rs` | gathering, iteration k = k bounces | Cohen & Wallace 1993 §5.3 |
//! | `chebyshev` | `chebyshev.rs` | Jacobi accelerated by Chebyshev polynomials | Golub & Varga 1961 |
//! | `gauss-seidel` | `gauss_seidel.rs` | gathering with updated values | Cohen & Greenberg 1985 |
//! | `shooting` | `shooting.rs` | every element shoots its unshot power per sweep (power formulation) | Cohen et al. 1988 |
//! | `progressive` | `progressive.rs` | shoot the largest unshot power (Southwell) + ambient | Cohen et al. 1988 |
//! | `stochastic-jacobi` | `stochastic_jacobi.rs` | Jacobi with rays, no form factors | Neumann et al. 1994 |
//! | `stochastic-shooting` | `stochastic_shooting.rs` | incremental shooting with rays | Bekaert 1999 |
//!
//! The deterministic solvers work on a [`System`] (any [`Transport`]); the stochastic ones
//! never store form factors and need the geometry instead: [`stochastic::solve`].
//!
//! **Residual.** Gathering solvers report the relative power residual
//! `Σ_i A_i·lum|E_i + ρ_i (F B)_i − B_i| / Σ_i A_i·lum(E_i)`: the fraction of the emitted
//! power the next Jacobi step would still add. Shooting solvers report their unshot power
//! `Σ_i A_i·lum(ΔB_i) / Σ_i A_i·lum(E_i)`, which bounds the same quantity (the residual of
//! a shooting iterate is `ρ·F·ΔB`, whose power is at most that of `ΔB`). Both are 1 for
//! `B = 0` and fall to 0, so one tolerance means the same thing for every solver.
//!
//! **Energy.** Every [`Solution`] carries its [`EnergyBalance`]: emitted = absorbed +
//! escaped + unshot, computed in the formulation the solver uses (see [`EnergyBalance`]).
//!
//! **Guards.** A solver cannot return a wrong answer quietly: its inputs must be finite
//! (E ≥ 0, 0 ≤ ρ < 1, areas ≥ 0), and after every iteration the [`Monitor`] stops with
//! [`Error::Diverged`] when the residual is not finite, when it has risen for
//! [`RISING_LIMIT`] records in a row to more than twice its lowest value, or (deterministic
//! solvers) when some radiosity exceeds the physical bound `max E / (1 − max ρ)` — which
//! holds for every solution of a system whose rows sum to at most 1, as the form-factor
//! row guard ensures.
//!
//! **Observing.** [`solve_observed`] calls an observer after every iteration (every bounce;
//! for progressive refinement after 1, 2, 4 … shots and then every `n` shots) with the
//! current display radiosity, so that a program can draw light flowing into the scene.
//! Time spent in the observer is not counted in the solver's timings or time budget.

mod chebyshev;
mod direct;
mod gauss_seidel;
mod jacobi;
mod progressive;
mod shooting;
pub mod stochastic;
mod stochastic_jacobi;
mod stochastic_shooting;

use std::borrow::Cow;
use std::str::FromStr;
use std::time::{Duration, Instant};

use crate::transport::{SparseRows, Transport};
use crate::{luminance, Error, Progress, Result, Rgb};

pub use direct::{check_memory as direct_check_memory, memory_bytes as direct_memory_bytes};
pub use stochastic::RaySystem;

/// The linear system to solve.
pub struct System<'a> {
    /// The transport operator `F`.
    pub transport: &'a dyn Transport,
    /// Reflectance ρ per element.
    pub reflectance: &'a [Rgb],
    /// Emitted exitance E = π·L_e per element.
    pub emission: &'a [Rgb],
    /// Element areas.
    pub area: &'a [f64],
}

impl System<'_> {
    /// Number of unknowns.
    pub fn len(&self) -> usize {
        self.emission.len()
    }
    /// True if there are none.
    pub fn is_empty(&self) -> bool {
        self.emission.is_empty()
    }
    /// Total emitted power per channel, Σ A_i E_i.
    pub fn emitted_power(&self) -> Rgb {
        self.emission.iter().zip(self.area).map(|(e, a)| *e * *a).sum()
    }
    /// The relative power residual of `b` (see the module docs), with `fb = F·b`.
    pub fn residual_with(&self, b: &[Rgb], fb: &[Rgb]) -> f64 {
        let mut num = 0.0;
        for i in 0..b.len() {
            let r = self.emission[i] + self.reflectance[i] * fb[i] - b[i];
            num += self.area[i] * luminance(r.abs());
        }
        num / luminance(self.emitted_power()).max(f64::MIN_POSITIVE)
    }
    /// The relative power residual of `b`.
    pub fn residual(&self, b: &[Rgb]) -> f64 {
        let mut fb = vec![Rgb::ZERO; b.len()];
        self.transport.gather(b, &mut fb);
        self.residual_with(b, &fb)
    }
    /// The explicit rows of `F`, or an error naming the solver that needs them.
    fn rows(&self, solver: Solver) -> Result<&SparseRows> {
        self.transport.rows().ok_or_else(|| {
            Error::Invalid(format!("the {} solver needs a transport operator with explicit rows", solver.name()))
        })
    }
}

/// A solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    /// Direct solution `B = (I − ρF)⁻¹E` by LU factorisation (small systems only).
    Direct,
    /// Jacobi iteration (gathering): iteration k holds k bounces of light.
    Jacobi,
    /// Chebyshev semi-iteration: Jacobi accelerated by Chebyshev polynomials (Golub &
    /// Varga 1961), the same product per sweep, about half the sweeps.
    Chebyshev,
    /// Gauss–Seidel iteration (gathering, updated values used at once).
    GaussSeidel,
    /// Shooting in the power formulation: each sweep, every element sends its unshot power.
    Shooting,
    /// Progressive refinement: shoot the element with the largest unshot power
    /// (Cohen, Chen, Wallace & Greenberg 1988).
    Progressive,
    /// Stochastic Jacobi: power distributed by rays, no form factors (Neumann et al. 1994).
    StochasticJacobi,
    /// Stochastic incremental shooting: unshot power distributed by rays (Bekaert 1999).
    StochasticShooting,
}

impl Solver {
    /// Every solver, in documentation order.
    pub const ALL: [Solver; 8] = [
        Solver::Direct,
        Solver::Jacobi,
        Solver::Chebyshev,
        Solver::GaussSeidel,
        Solver::Shooting,
        Solver::Progressive,
        Solver::StochasticJacobi,
        Solver::StochasticShooting,
    ];
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Direct => "direct",
            Solver::Jacobi => "jacobi",
            Solver::Chebyshev => "chebyshev",
            Solver::GaussSeidel => "gauss-seidel",
            Solver::Shooting => "shooting",
            Solver::Progressive => "progressive",
            Solver::StochasticJacobi => "stochastic-jacobi",
            Solver::StochasticShooting => "stochastic-shooting",
        }
    }
    /// True for the Monte Carlo solvers, which need geometry ([`stochastic::solve`]) and no
    /// form factors.
    pub fn is_stochastic(self) -> bool {
        matches!(self, Solver::StochasticJacobi | Solver::StochasticShooting)
    }
}

impl std::fmt::Display for Solver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Solver {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Solver::ALL.iter().copied().find(|m| m.name() == s).ok_or_else(|| {
            let names: Vec<_> = Solver::ALL.iter().map(|m| m.name()).collect();
            Error::Invalid(format!("unknown solver '{s}' (known: {})", names.join(", ")))
        })
    }
}

/// The default memory limit of the direct solver: 2 GiB (a 16 384-element dense matrix).
pub const DIRECT_MEMORY_LIMIT: u64 = 2 << 30;

/// When to stop, and the solvers' own settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Stop once the relative power residual (or unshot power) is at most this.
    pub tolerance: f64,
    /// Stop after this many iterations: sweeps (bounces) for the gathering and shooting
    /// solvers, ray iterations for the stochastic ones, and for progressive refinement
    /// sweeps of `n` shots (`n` elements) — its reported iterations are single shots, so
    /// it stops after at most `max_iterations × n` of them (its history's `sweeps` column
    /// is the comparable count).
    pub max_iterations: usize,
    /// Stop after this much solver time.
    pub time_budget: Option<Duration>,
    /// Seed of the stochastic solvers; their results do not depend on the thread count.
    pub seed: u64,
    /// Stochastic solvers: rays per iteration for the full emitted power (None: 500 per
    /// element, at least 200 000).
    pub rays: Option<u64>,
    /// Direct solver: refuse systems whose dense matrix needs more bytes than this.
    pub direct_memory_limit: u64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            tolerance: 1e-4,
            max_iterations: 1000,
            time_budget: None,
            seed: 0,
            rays: None,
            direct_memory_limit: DIRECT_MEMORY_LIMIT,
        }
    }
}

/// Why a solver stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// The residual reached the tolerance (or, for stochastic Jacobi, its noise level).
    Converged,
    /// The iteration cap was reached.
    MaxIterations,
    /// The time budget ran out.
    TimeBudget,
    /// The user interrupted.
    Interrupted,
}

/// One iteration's record.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct IterationRecord {
    /// 1-based iteration number (progressive refinement: shots).
    pub iteration: usize,
    /// The same in sweeps: `iteration`, or shots / n for progressive refinement.
    pub sweeps: f64,
    /// Relative residual (or unshot power) after it.
    pub residual: f64,
    /// Solver seconds since the solve started.
    pub seconds: f64,
    /// Rays cast by the solver so far (stochastic solvers).
    pub rays: u64,
}

/// The current state, handed to an observer after an iteration.
#[derive(Clone, Copy, Debug)]
pub struct IterationState<'a> {
    /// The solver.
    pub solver: Solver,
    /// 1-based iteration number (progressive refinement: shots).
    pub iteration: usize,
    /// Relative residual (or unshot power).
    pub residual: f64,
    /// Solver seconds so far.
    pub seconds: f64,
    /// Rays cast so far.
    pub rays: u64,
    /// Radiosity per element for display (with the ambient term for progressive
    /// refinement), same units as E.
    pub radiosity: &'a [Rgb],
}

/// Called after iterations (see the module docs).
pub type Observer<'a> = dyn FnMut(&IterationState<'_>) + 'a;

/// Energy bookkeeping of a solution, power per RGB channel (W or scene units):
/// `emitted = absorbed + escaped + back_faces + unshot`.
///
/// With `S` the radiosity already passed on ("shot") and `ΔB = B − S` the part still to pass
/// on, the power arriving at the elements is `H = F·S` (gathering solvers, rows of F) or
/// `P_i = Σ_j A_j S_j F_ji` (power formulation, senders' rows); the absorbed power is
/// `Σ (1−ρ_i)·arriving_i`, the escaped power is what was shot but arrived nowhere (through
/// openings, or onto the back of one-sided surfaces), and the unshot power is `Σ A_i ΔB_i`.
/// Gathering solvers (direct, Jacobi, Gauss–Seidel) shoot all of `B` and count their
/// residual `E + ρFB − B` as unshot; progressive refinement and shooting count their
/// unshot radiosity; the stochastic solvers count what their rays carried.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyBalance {
    /// Emitted power Σ A_i E_i.
    pub emitted: Rgb,
    /// Absorbed by the surfaces.
    pub absorbed: Rgb,
    /// Left the scene through openings (or, until [`crate::back_faces::split_escaped`]
    /// has run, also onto the back of one-sided surfaces).
    pub escaped: Rgb,
    /// Absorbed by the back faces of one-sided surfaces (see [`crate::back_faces`]).
    pub back_faces: Rgb,
    /// Received but not yet passed on (the unconverged part).
    pub unshot: Rgb,
}

impl EnergyBalance {
    /// `emitted − absorbed − escaped − unshot`: zero up to rounding when the books close.
    pub fn imbalance(&self) -> Rgb {
        self.emitted - self.absorbed - self.escaped - self.back_faces - self.unshot
    }
    /// The largest channel of |imbalance| relative to the emitted power of that channel.
    pub fn relative_imbalance(&self) -> f64 {
        let d = self.imbalance().abs();
        (0..3).map(|c| if self.emitted[c] > 0.0 { d[c] / self.emitted[c] } else { d[c] }).fold(0.0, f64::max)
    }
}

/// The result of a solve.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Radiosity B per element (exitance, same units as E).
    pub radiosity: Vec<Rgb>,
    /// For progressive refinement: the ambient term (per element, ρ_i·ambient) that
    /// estimates the light not yet shot; added for display only.
    pub ambient: Option<Vec<Rgb>>,
    /// Energy bookkeeping.
    pub energy: EnergyBalance,
    /// Statistics.
    pub stats: SolveStats,
}

impl Solution {
    /// Radiosity plus the ambient estimate (if any), for display.
    pub fn display_radiosity(&self) -> Vec<Rgb> {
        match &self.ambient {
            Some(a) => self.radiosity.iter().zip(a).map(|(b, a)| *b + *a).collect(),
            None => self.radiosity.clone(),
        }
    }
}

/// What the solver did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SolveStats {
    /// Solver name.
    pub solver: String,
    /// Iterations done (progressive refinement: shots).
    pub iterations: usize,
    /// Final relative residual (see module docs).
    pub residual: f64,
    /// Why it stopped.
    pub stop: StopReason,
    /// Solver seconds (wall clock, observer time excluded).
    pub seconds: f64,
    /// Rays cast (stochastic solvers).
    pub rays: u64,
    /// Stochastic solvers: estimated relative RMS error of B (area-weighted luminance),
    /// from the spread of independent replicas.
    pub error_estimate: Option<f64>,
    /// Per-iteration history.
    pub history: Vec<IterationRecord>,
}

impl SolveStats {
    /// The first recorded time (seconds) and sweeps at which the residual was at most
    /// `level`, if it got there.
    pub fn reached(&self, level: f64) -> Option<(f64, f64)> {
        self.history.iter().find(|r| r.residual <= level).map(|r| (r.seconds, r.sweeps))
    }
}

/// Solves `system` with a deterministic `solver`.
pub fn solve(solver: Solver, system: &System, opts: &Options, progress: &dyn Progress) -> Result<Solution> {
    solve_observed(solver, system, opts, progress, None)
}

/// Solves `system` with a deterministic `solver`, calling `observer` after iterations.
pub fn solve_observed(
    solver: Solver,
    system: &System,
    opts: &Options,
    progress: &dyn Progress,
    observer: Option<&mut Observer<'_>>,
) -> Result<Solution> {
    let n = system.len();
    if system.transport.len() != n || system.reflectance.len() != n || system.area.len() != n {
        return Err(Error::Invalid("solve: system sizes disagree".into()));
    }
    check_inputs(system)?;
    let mut mon = Monitor::new(solver, opts, progress, observer);
    mon.bound = radiosity_bound(system.emission, system.reflectance);
    match solver {
        Solver::Direct => direct::solve(system, &mut mon),
        Solver::Jacobi => jacobi::solve(system, &mut mon),
        Solver::Chebyshev => chebyshev::solve(system, &mut mon),
        Solver::GaussSeidel => gauss_seidel::solve(system, &mut mon),
        Solver::Shooting => shooting::solve(system, &mut mon),
        Solver::Progressive => progressive::solve(system, &mut mon),
        Solver::StochasticJacobi | Solver::StochasticShooting => Err(Error::Invalid(format!(
            "the {solver} solver casts rays and needs the geometry: use solve::stochastic::solve"
        ))),
    }
}

/// Records in a row with a rising residual after which a solve counts as diverging (when
/// the residual is also above twice its lowest value).
pub const RISING_LIMIT: usize = 5;

/// One gathering sweep's product and bookkeeping, shared by Jacobi and Chebyshev:
/// `fb = F·b`, the residual of `b` from it, watched by the divergence guard, recorded and
/// observed (from the first iteration on) and checked against the stopping rules.
/// Returns the residual and why to stop, if so.
fn gather_sweep(sys: &System, mon: &mut Monitor, it: usize, b: &[Rgb], fb: &mut [Rgb]) -> Result<(f64, Option<StopReason>)> {
    sys.transport.gather(b, fb);
    let residual = sys.residual_with(b, fb);
    mon.watch(residual, Some(b))?;
    if it > 0 {
        mon.record(it, it as f64, residual);
        mon.observe(it, residual, || Cow::Borrowed(b));
    }
    Ok((residual, mon.check(it, residual)))
}

/// Checks that the system's inputs are finite and physical.
fn check_inputs(sys: &System) -> Result<()> {
    let bad = |what: &str, i: usize, v: String| {
        Err(Error::Diverged { why: format!("solver input: {what} of element {i} is {v}"), elements: vec![i], places: Vec::new() })
    };
    for i in 0..sys.len() {
        let (e, r, a) = (sys.emission[i], sys.reflectance[i], sys.area[i]);
        if !e.is_finite() || e.min_element() < 0.0 {
            return bad("emission", i, format!("{e}"));
        }
        if !r.is_finite() || r.min_element() < 0.0 || r.max_element() >= 1.0 {
            return bad("reflectance", i, format!("{r}"));
        }
        if !a.is_finite() || a < 0.0 {
            return bad("area", i, format!("{a}"));
        }
    }
    Ok(())
}

/// The physical bound on radiosity, `max E / (1 − max ρ)` (largest channel), for a system
/// whose rows sum to at most 1; infinite when nothing reflects less than 1.
pub fn radiosity_bound(emission: &[Rgb], reflectance: &[Rgb]) -> f64 {
    let e = emission.iter().fold(0.0f64, |m, e| m.max(e.max_element()));
    let r = reflectance.iter().fold(0.0f64, |m, r| m.max(r.max_element()));
    if r < 1.0 {
        e / (1.0 - r)
    } else {
        f64::INFINITY
    }
}

/// The elements with the largest radiosity, worst first (at most `k`).
fn worst_elements(b: &[Rgb], k: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..b.len()).collect();
    let key = |i: usize| if b[i].is_finite() { b[i].max_element() } else { f64::INFINITY };
    idx.sort_by(|&x, &y| key(y).total_cmp(&key(x)));
    idx.truncate(k);
    idx
}

/// The bookkeeping every solver shares: the clock (minus observer time), the history,
/// progress messages, the observer and the stopping rules.
pub(crate) struct Monitor<'a, 'o> {
    solver: Solver,
    pub(crate) opts: &'a Options,
    pub(crate) progress: &'a dyn Progress,
    observer: Option<&'a mut Observer<'o>>,
    start: Instant,
    excluded: Duration,
    history: Vec<IterationRecord>,
    /// Rays cast so far.
    pub(crate) rays: u64,
    /// Lowest residual so far, the last one, and records in a row that rose.
    lowest: f64,
    last: f64,
    rising: usize,
    /// The physical bound on radiosity (infinite: not checked).
    pub(crate) bound: f64,
}

impl<'a, 'o> Monitor<'a, 'o> {
    pub(crate) fn new(
        solver: Solver,
        opts: &'a Options,
        progress: &'a dyn Progress,
        observer: Option<&'a mut Observer<'o>>,
    ) -> Self {
        Monitor {
            solver,
            opts,
            progress,
            observer,
            start: Instant::now(),
            excluded: Duration::ZERO,
            history: Vec::new(),
            rays: 0,
            lowest: f64::INFINITY,
            last: f64::INFINITY,
            rising: 0,
            bound: f64::INFINITY,
        }
    }

    /// The divergence guard, after an iteration with `residual` (see the module docs):
    /// `radiosity` is checked against [`Monitor::bound`] and for non-finite values.
    pub(crate) fn watch(&mut self, residual: f64, radiosity: Option<&[Rgb]>) -> Result<()> {
        let diverged = |why: String, b: Option<&[Rgb]>| Error::Diverged {
            why: format!("the {} solve diverged: {why}", self.solver),
            elements: b.map(|b| worst_elements(b, 3)).unwrap_or_default(),
            places: Vec::new(),
        };
        if !residual.is_finite() {
            return Err(diverged(format!("the residual is {residual}"), radiosity));
        }
        if residual > self.last * (1.0 + 1e-12) {
            self.rising += 1;
        } else {
            self.rising = 0;
        }
        self.last = residual;
        self.lowest = self.lowest.min(residual);
        // Stochastic residuals are estimates with noise: only a tenfold rise counts.
        let factor = if self.solver.is_stochastic() { 10.0 } else { 2.0 };
        if self.rising >= RISING_LIMIT && residual > factor * self.lowest {
            return Err(diverged(
                format!(
                    "the residual rose for {} iterations in a row, from {:.3e} to {residual:.3e}",
                    self.rising, self.lowest
                ),
                radiosity,
            ));
        }
        if let Some(b) = radiosity {
            if let Some(i) = b.iter().position(|x| !x.is_finite()) {
                return Err(diverged(format!("element {i} has radiosity {}", b[i]), radiosity));
            }
            let scale = if self.bound.is_finite() { self.bound } else { b.iter().fold(0.0f64, |m, x| m.max(x.abs().max_element())) };
            if let Some(i) = b.iter().position(|x| x.min_element() < -1e-9 * scale) {
                return Err(diverged(format!("element {i} has negative radiosity {}", b[i]), radiosity));
            }
            if self.bound.is_finite() {
                let (i, m) = b.iter().enumerate().fold((0, 0.0), |acc, (i, x)| if x.max_element() > acc.1 { (i, x.max_element()) } else { acc });
                if m > self.bound * (1.0 + 1e-6) + 1e-300 {
                    return Err(diverged(
                        format!(
                            "element {i} has radiosity {m:.6e}, above the physical bound max E/(1 − max ρ) = {:.6e}",
                            self.bound
                        ),
                        radiosity,
                    ));
                }
            }
        }
        Ok(())
    }

    fn elapsed(&self) -> Duration {
        self.start.elapsed().saturating_sub(self.excluded)
    }

    /// Solver seconds so far.
    pub(crate) fn seconds(&self) -> f64 {
        self.elapsed().as_secs_f64()
    }

    /// True once the time budget is spent.
    pub(crate) fn over_budget(&self) -> bool {
        self.opts.time_budget.is_some_and(|b| self.elapsed() >= b)
    }

    /// True when an observer wants the radiosity after iterations.
    pub(crate) fn observing(&self) -> bool {
        self.observer.is_some()
    }

    /// Records iteration `iteration` (in the solver's units; `sweeps` the same in sweeps).
    pub(crate) fn record(&mut self, iteration: usize, sweeps: f64, residual: f64) {
        let rec = IterationRecord { iteration, sweeps, residual, seconds: self.seconds(), rays: self.rays };
        self.history.push(rec);
        let what = if self.solver == Solver::Progressive { "shots" } else { "iteration" };
        let rays = if self.rays > 0 { format!(", {} rays", self.rays) } else { String::new() };
        self.progress.message(&format!("{} {what} {iteration}: residual {residual:.3e}{rays}", self.solver));
    }

    /// Hands the current display radiosity to the observer, if any (computed only then).
    pub(crate) fn observe<'b>(&mut self, iteration: usize, residual: f64, radiosity: impl FnOnce() -> Cow<'b, [Rgb]>) {
        if self.observer.is_none() {
            return;
        }
        let t = Instant::now();
        let b = radiosity();
        let state = IterationState {
            solver: self.solver,
            iteration,
            residual,
            seconds: self.seconds(),
            rays: self.rays,
            radiosity: &b,
        };
        if let Some(obs) = self.observer.as_mut() {
            obs(&state);
        }
        self.excluded += t.elapsed();
    }

    /// The stopping rules, checked after `iteration` (0 = before the first) with its
    /// residual: tolerance, then the iteration cap, an interrupt, the time budget.
    pub(crate) fn check(&self, iteration: usize, residual: f64) -> Option<StopReason> {
        if residual <= self.opts.tolerance {
            Some(StopReason::Converged)
        } else if iteration >= self.opts.max_iterations {
            Some(StopReason::MaxIterations)
        } else {
            self.interrupted()
        }
    }

    /// An interrupt or the end of the time budget (checked inside long iterations).
    pub(crate) fn interrupted(&self) -> Option<StopReason> {
        if self.progress.should_stop() {
            Some(StopReason::Interrupted)
        } else if self.over_budget() {
            Some(StopReason::TimeBudget)
        } else {
            None
        }
    }

    /// The statistics of the finished solve.
    pub(crate) fn finish(&mut self, iterations: usize, residual: f64, stop: StopReason, error_estimate: Option<f64>) -> SolveStats {
        SolveStats {
            solver: self.solver.name().to_string(),
            iterations,
            residual,
            stop,
            seconds: self.seconds(),
            rays: self.rays,
            error_estimate,
            history: std::mem::take(&mut self.history),
        }
    }
}

/// Energy balance in the gathering formulation. With `unshot = Some(ΔB)` the shot part is
/// `S = B − ΔB` (progressive refinement); with `None`, `S = B` and the residual
/// `E + ρFB − B` is the unshot part (direct, Jacobi, Gauss–Seidel).
pub(crate) fn energy_gathering(sys: &System, b: &[Rgb], unshot: Option<&[Rgb]>) -> EnergyBalance {
    let n = b.len();
    let shot: Cow<[Rgb]> = match unshot {
        Some(u) => Cow::Owned(b.iter().zip(u).map(|(b, u)| *b - *u).collect()),
        None => Cow::Borrowed(b),
    };
    let mut h = vec![Rgb::ZERO; n];
    sys.transport.gather(&shot, &mut h);
    let mut out = EnergyBalance { emitted: sys.emitted_power(), ..Default::default() };
    let mut leaving = Rgb::ZERO;
    let mut arriving = Rgb::ZERO;
    for i in 0..n {
        let a = sys.area[i];
        out.absorbed += (Rgb::ONE - sys.reflectance[i]) * h[i] * a;
        leaving += shot[i] * a;
        arriving += h[i] * a;
        out.unshot += match unshot {
            Some(u) => u[i] * a,
            None => (sys.emission[i] + sys.reflectance[i] * h[i] - b[i]) * a,
        };
    }
    out.escaped = leaving - arriving;
    out
}

/// Area-weighted relative RMS difference of the luminance of `b` from `reference`:
/// `sqrt(Σ A_i lum(b_i − r_i)² / Σ A_i lum(r_i)²)`.
pub fn relative_difference(area: &[f64], b: &[Rgb], reference: &[Rgb]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for i in 0..b.len() {
        num += area[i] * luminance(b[i] - reference[i]).powi(2);
        den += area[i] * luminance(reference[i]).powi(2);
    }
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

/// The largest relative difference of any channel of any element:
/// `max_i,c |b_ic − r_ic| / |r_ic|` (values below 1e-12 of the channel's largest count as
/// that floor, so black elements do not divide by zero).
pub fn max_relative_difference(b: &[Rgb], reference: &[Rgb]) -> f64 {
    let scale = reference.iter().fold(Rgb::ZERO, |m, r| m.max(r.abs()));
    let floor = (scale * 1e-12).max(Rgb::splat(f64::MIN_POSITIVE));
    b.iter().zip(reference).map(|(b, r)| ((*b - *r).abs() / r.abs().max(floor)).max_element()).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests;
