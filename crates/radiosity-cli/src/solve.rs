//! `radiosity solve`: solve a scene and write the report.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use radiosity::pipeline::solve_scene;

use crate::common::{exit_code, write_atomic, SolveFlags};
use crate::progress::CliProgress;

/// Flags of `radiosity solve`.
#[derive(Args, Debug)]
pub struct SolveArgs {
    #[command(flatten)]
    pub solve: SolveFlags,
}

pub fn run(a: SolveArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let settings = a.solve.settings()?;
    a.solve.init_threads()?;
    let (scene, load_s) = a.solve.load_scene()?;
    let progress = CliProgress::new(a.solve.quiet);
    let solved = solve_scene(scene, &settings, &progress)?;
    let mut report = solved.report();
    report.timings.load = load_s;
    report.timings.total = t0.elapsed().as_secs_f64();
    let json = serde_json::to_string_pretty(&report)?;
    match &a.solve.report {
        Some(p) => write_atomic(p, json.as_bytes())?,
        None => println!("{json}"),
    }
    if !a.solve.quiet {
        let s = &solved.solution.stats;
        eprintln!(
            "{} elements, {} {} iterations, residual {:.2e} ({:?}), {:.2} s",
            solved.mesh.len(),
            s.solver,
            s.iterations,
            s.residual,
            s.stop,
            report.timings.total
        );
    }
    Ok(exit_code(solved.solution.stats.stop))
}
