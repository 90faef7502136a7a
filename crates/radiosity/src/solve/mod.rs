//! Stage 5: solving `B = E + ρ·F·B` for the radiosity `B` of every element, per RGB channel.
//!
//! Every solver is a runtime choice ([`Solver`]), works on any [`Transport`], reports its
//! residual after every iteration, and stops on a tolerance, an iteration cap, a time budget
//! or an interrupt ([`Progress::should_stop`]) — keeping the best solution so far.
//!
//! Residual: the relative power residual
//! `Σ_i A_i·lum|E_i + ρ_i (F B)_i − B_i| / Σ_i A_i·lum(E_i)`, i.e. the fraction of the
//! emitted power not yet accounted for. Progressive refinement reports its unshot power
//! `Σ_i A_i·lum(ΔB_i) / Σ_i A_i·lum(E_i)`, which bounds the same quantity.

mod jacobi;
mod progressive;

use std::str::FromStr;
use std::time::{Duration, Instant};

use crate::transport::Transport;
use crate::{luminance, Error, Progress, Result, Rgb};

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
}

/// A solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    /// Jacobi iteration (gathering): iteration k holds k bounces of light.
    Jacobi,
    /// Progressive refinement: shoot the element with the largest unshot power
    /// (Cohen, Chen, Wallace & Greenberg 1988).
    Progressive,
}

impl Solver {
    /// Every solver.
    pub const ALL: [Solver; 2] = [Solver::Jacobi, Solver::Progressive];
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Jacobi => "jacobi",
            Solver::Progressive => "progressive",
        }
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

/// When to stop.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Stop once the relative power residual is at most this.
    pub tolerance: f64,
    /// Stop after this many iterations (Jacobi sweeps; for progressive refinement, shots
    /// are counted in units of `n` shots).
    pub max_iterations: usize,
    /// Stop after this much time.
    pub time_budget: Option<Duration>,
}

impl Default for Options {
    fn default() -> Self {
        Options { tolerance: 1e-4, max_iterations: 1000, time_budget: None }
    }
}

/// Why a solver stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// The residual reached the tolerance.
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
    /// 1-based iteration number.
    pub iteration: usize,
    /// Relative residual (or unshot power) after it.
    pub residual: f64,
    /// Seconds since the solve started.
    pub seconds: f64,
}

/// The result of a solve.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Radiosity B per element (exitance, same units as E).
    pub radiosity: Vec<Rgb>,
    /// For progressive refinement: the ambient term (per element, ρ_i·ambient) that
    /// estimates the light not yet shot; added for display only.
    pub ambient: Option<Vec<Rgb>>,
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
    /// Iterations done.
    pub iterations: usize,
    /// Final relative residual (see module docs).
    pub residual: f64,
    /// Why it stopped.
    pub stop: StopReason,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Per-iteration history.
    pub history: Vec<IterationRecord>,
}

/// Solves `system` with `solver`.
pub fn solve(solver: Solver, system: &System, opts: &Options, progress: &dyn Progress) -> Result<Solution> {
    if system.transport.len() != system.len() || system.reflectance.len() != system.len() || system.area.len() != system.len() {
        return Err(Error::Invalid("solve: system sizes disagree".into()));
    }
    let clock = Clock { start: Instant::now(), budget: opts.time_budget };
    match solver {
        Solver::Jacobi => jacobi::solve(system, opts, &clock, progress),
        Solver::Progressive => progressive::solve(system, opts, &clock, progress),
    }
}

pub(crate) struct Clock {
    start: Instant,
    budget: Option<Duration>,
}

impl Clock {
    pub(crate) fn seconds(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
    pub(crate) fn over_budget(&self) -> bool {
        self.budget.is_some_and(|b| self.start.elapsed() >= b)
    }
}
