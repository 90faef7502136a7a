//! `radiosity` — the command-line program. Only this crate prints, draws progress bars and
//! picks exit codes; the work is done by the `radiosity` library.
//!
//! One file per subcommand; each parses raw flags (clap) and validates them into the
//! library's settings before any work starts.

mod bake;
mod bench;
mod common;
mod compare;
mod plot;
mod progress;
mod render;
mod solve;
mod thermal;
mod viewfactors;

use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};

/// Radiosity: diffuse global illumination by the finite-element method.
#[derive(Parser)]
#[command(name = "radiosity", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Solve a scene and render an image (PNG, optionally EXR) and a report.
    Render(render::RenderArgs),
    /// Solve a scene and write the report (per-object radiance, convergence, timings).
    Solve(solve::SolveArgs),
    /// Solve a scene and write it with its light baked in: glTF binary (.glb) with
    /// per-vertex COLOR_0, for three.js, Blender, Godot, Unity.
    Bake(bake::BakeArgs),
    /// Compare a rendered EXR with a reference EXR (relative RMSE, light-masked too).
    Compare(compare::CompareArgs),
    /// Compute a view-factor matrix (CSV, NumPy .npy, JSON or View3D text) with diagnostics.
    Viewfactors(viewfactors::ViewfactorsArgs),
    /// Net radiative heat exchange between grey surfaces at given temperatures or heat
    /// fluxes: per surface T, q, Q, J, G and the heat balance.
    Thermal(thermal::ThermalArgs),
    /// Benchmarks (`bench rays`: BVH throughput on incoherent rays, against Embree with
    /// `--features embree`).
    Bench(bench::BenchArgs),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    progress::install_ctrlc();
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Solve(a) => solve::run(a),
        Command::Bake(a) => bake::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Viewfactors(a) => viewfactors::run(a),
        Command::Thermal(a) => thermal::run(a),
        Command::Bench(a) => bench::run(a),
    };
    match result {
        Ok(code) => code,
        // Interrupted before any usable result existed (e.g. during form factors).
        Err(e) if matches!(e.downcast_ref::<radiosity::Error>(), Some(radiosity::Error::Cancelled)) => {
            eprintln!("interrupted before a solution existed: nothing written");
            ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Clap's own answer to bad arguments, except for a flag that another subcommand takes:
/// clap would point to the nearest spelling among this subcommand's flags (`solve --frames`:
/// "a similar argument exists: '--rays'"); the user meant the other subcommand's flag.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    if e.kind() == ErrorKind::UnknownArgument {
        if let (Some(ContextValue::String(arg)), Some(current)) = (e.get(ContextKind::InvalidArg), std::env::args_os().nth(1).and_then(|a| a.into_string().ok())) {
            let flag = arg.split('=').next().unwrap_or(arg);
            let cmd = Cli::command();
            let takes = |s: &clap::Command| {
                s.get_arguments().any(|a| {
                    a.get_long().is_some_and(|l| flag == format!("--{l}")) || a.get_short().is_some_and(|c| flag == format!("-{c}"))
                })
            };
            let mine = cmd.find_subcommand(&current);
            let owners: Vec<&str> =
                cmd.get_subcommands().filter(|s| s.get_name() != current && takes(s)).map(|s| s.get_name()).collect();
            // A subcommand with subcommands of its own (`bench rays`): clap's answer.
            if let (Some(false), false) = (mine.map(|m| m.has_subcommands()), owners.is_empty()) {
                let owners: Vec<String> = owners.iter().map(|o| format!("`radiosity {o}`")).collect();
                eprintln!(
                    "error: `{flag}` is not an option of `radiosity {current}`; {} {} it\n\nFor the options of `{current}`, try 'radiosity {current} --help'.",
                    owners.join(" and "),
                    if owners.len() == 1 { "takes" } else { "take" }
                );
                return ExitCode::from(2);
            }
        }
    }
    e.exit()
}
