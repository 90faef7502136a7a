//! `radiosity solve`: solve a scene and write the report; `--solver all` runs every solver
//! on the scene and `--plot` draws their convergence.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use radiosity::pipeline::{solve_all, solve_scene};
use radiosity::report::{ComparisonRow, Report};
use radiosity::solve::StopReason;

use crate::common::{energy_summary, exit_code, write_atomic, Outputs, SolveFlags};
use crate::plot::{convergence_png, Series};
use crate::progress::CliProgress;

/// Flags of `radiosity solve`.
#[derive(Args, Debug)]
pub struct SolveArgs {
    #[command(flatten)]
    pub solve: SolveFlags,
    /// Plot residual against time and iterations (PNG), one line per solver (with
    /// `--solver all`: every solver).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
}

pub fn run(a: SolveArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let settings = a.solve.settings()?;
    // Outputs are checked before any work.
    let mut outputs = Outputs::default();
    if let Some(p) = &a.solve.report {
        outputs.add("--report", p);
    }
    if let Some(p) = &a.plot {
        outputs.add_format("--plot", p, "png", "PNG");
    }
    outputs.check()?;
    a.solve.init_threads()?;
    let (scene, load_s) = a.solve.load_scene()?;
    let progress = CliProgress::new(a.solve.quiet);
    let (mut report, series, stop) = if a.solve.all_solvers() {
        let cmp = solve_all(scene, &settings, &progress)?;
        let report = cmp.report();
        let series = cmp
            .runs
            .iter()
            .filter_map(|r| r.outcome.as_ref().ok().map(|s| Series { label: r.solver.name().into(), history: s.stats.history.clone() }))
            .collect::<Vec<_>>();
        let stop = if cmp.runs.iter().any(|r| r.outcome.as_ref().is_ok_and(|s| s.stats.stop == StopReason::Interrupted)) {
            StopReason::Interrupted
        } else {
            StopReason::Converged
        };
        (report, series, stop)
    } else {
        let solved = solve_scene(scene, &settings, &progress)?;
        let s = &solved.solution.stats;
        let series = vec![Series { label: s.solver.clone(), history: s.history.clone() }];
        (solved.report(), series, s.stop)
    };
    report.timings.load = load_s;
    if let Some(p) = &a.plot {
        let title = format!("{}: {} elements", report.scene, report.elements);
        write_atomic(p, &convergence_png(&title, &series, 1200, 520)?)?;
        report.images.push(p.display().to_string());
    }
    report.timings.stages = progress.stages();
    report.timings.total = t0.elapsed().as_secs_f64();
    let json = serde_json::to_string_pretty(&report)?;
    match &a.solve.report {
        Some(p) => write_atomic(p, json.as_bytes())?,
        None => println!("{json}"),
    }
    if !a.solve.quiet {
        summary(&report);
    }
    Ok(exit_code(stop))
}

/// The summary on stderr: one line per solver, the energy balance.
fn summary(report: &Report) {
    if !report.comparison.is_empty() {
        eprintln!("{}", table(&report.comparison));
        eprintln!("reference: {}", report.reference_solver.as_deref().unwrap_or("-"));
        if report.comparison.iter().any(|r| r.solver == "progressive" && r.stats.is_some()) {
            eprintln!(
                "progressive's iterations are single shots ({} per sweep); --max-iterations counts sweeps for every solver",
                report.elements
            );
        }
    } else if let Some(s) = &report.solver {
        let err = s.error_estimate.map(|e| format!(", error ≈ {:.2} %", 100.0 * e)).unwrap_or_default();
        let rays = if s.rays > 0 { format!(", {} rays", s.rays) } else { String::new() };
        eprintln!(
            "{} elements, {} {} iterations, residual {:.2e} ({:?}){rays}{err}, solve {:.2} s",
            report.elements, s.solver, s.iterations, s.residual, s.stop, s.seconds
        );
    }
    if let Some(e) = &report.energy {
        eprintln!("{}", energy_summary(e));
    }
    eprintln!("total {:.2} s", report.timings.total);
}

/// The comparison table as text (also what BENCHMARKS.md quotes).
pub fn table(rows: &[ComparisonRow]) -> String {
    let mut out = format!(
        "{:<20} {:>7} {:>9} {:>10} {:>11} {:>10} {:>10} {:>9} {:>9}",
        "solver", "iters", "time s", "residual", "rays", "t(1e-3) s", "it(1e-3)", "vs ref", "error est"
    );
    let opt = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map(f).unwrap_or_else(|| "-".into());
    for r in rows {
        out.push('\n');
        match &r.stats {
            Some(s) => out.push_str(&format!(
                "{:<20} {:>7} {:>9.3} {:>10.2e} {:>11} {:>10} {:>10} {:>9} {:>9}",
                r.solver,
                s.iterations,
                s.seconds,
                s.residual,
                s.rays,
                opt(r.seconds_to_1e3, &|x| format!("{x:.3}")),
                opt(r.sweeps_to_1e3, &|x| format!("{x:.2}")),
                opt(r.difference_from_reference, &|x| format!("{x:.1e}")),
                opt(s.error_estimate, &|x| format!("{x:.1e}")),
            )),
            None => out.push_str(&format!("{:<20} {}", r.solver, r.error.as_deref().unwrap_or("no result"))),
        }
    }
    out
}
