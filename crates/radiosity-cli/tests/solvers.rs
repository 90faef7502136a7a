//! Issue 4: every solver name works from the command line, and `--solver all --plot`
//! writes the comparison table and a plot.

use std::path::Path;
use std::process::Command;

fn radiosity(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).current_dir(dir).output().expect("the program starts")
}

fn tempdir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("radiosity-solvers-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn every_solver_by_name_writes_a_report_with_its_energy_balance() {
    let dir = tempdir("names");
    for name in ["direct", "jacobi", "chebyshev", "gauss-seidel", "shooting", "progressive", "stochastic-jacobi", "stochastic-shooting"] {
        let out = radiosity(&dir, &["solve", "cornell", "--mesh-size", "150", "--solver", name, "--rays", "50000", "--report", "r.json"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{name}: {err}");
        assert!(err.contains("energy: emitted"), "{name}: {err}");
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("r.json")).unwrap()).unwrap();
        assert_eq!(r["solver"]["solver"], name);
        assert!(r["energy"]["imbalance"].as_f64().unwrap() < 1e-6, "{name}");
        // The stochastic solvers never compute form factors.
        assert_eq!(r["form_factors"].is_null(), name.starts_with("stochastic"), "{name}");
    }
    let out = radiosity(&dir, &["solve", "cornell", "--solver", "gauss_seidel"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("gauss-seidel"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn solver_all_plots_and_tabulates_every_solver() {
    let dir = tempdir("all");
    let out = radiosity(&dir, &["solve", "cornell", "--mesh-size", "150", "--solver", "all", "--rays", "400000", "--plot", "c.png", "--report", "r.json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let png = std::fs::read(dir.join("c.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG") && png.len() > 10_000);
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("r.json")).unwrap()).unwrap();
    assert_eq!(r["reference_solver"], "direct");
    let rows = r["comparison"].as_array().unwrap();
    assert_eq!(rows.len(), 8);
    for row in rows {
        let name = row["solver"].as_str().unwrap();
        if name == "stochastic-jacobi" {
            // Its residual estimate stops at its own noise level, ~1e-3 at these rays.
            assert!(row["stats"]["residual"].as_f64().unwrap() < 1e-2, "{name}");
        } else {
            assert!(row["seconds_to_residual_1e-3"].as_f64().is_some(), "{name} never reached 1e-3");
        }
        let diff = row["difference_from_reference"].as_f64().unwrap();
        // Gathering solvers agree with direct; shooting differs by F's reciprocity error,
        // the stochastic ones by their noise and F's.
        let bound = if ["jacobi", "chebyshev", "gauss-seidel", "progressive", "direct"].contains(&name) { 1e-3 } else { 0.05 };
        assert!(diff < bound, "{name}: {diff}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn render_refuses_solver_all() {
    let dir = tempdir("render-all");
    let out = radiosity(&dir, &["render", "cornell", "--solver", "all"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("radiosity solve"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn solver_all_max_iterations_caps_every_solver_in_its_documented_unit() {
    // Finding 12: `--max-iterations 5` under `--solver all` let progressive run 5 × n shots,
    // reported as thousands of "iterations". The cap is sweeps for every solver (n shots
    // for progressive, whose report counts shots); nothing runs past 5 sweeps.
    let dir = tempdir("all-max-iterations");
    let args = ["solve", "furnace", "--solver", "all", "--max-iterations", "5", "--tolerance", "0", "--mesh-size", "0.25"];
    let out = radiosity(&dir, &[&args[..], &["--rays", "20000", "--report", "r.json", "-q"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("r.json")).unwrap()).unwrap();
    let n = r["elements"].as_u64().unwrap();
    assert_eq!(n, 96);
    let rows = r["comparison"].as_array().unwrap();
    assert_eq!(rows.len(), 8);
    for row in rows {
        let name = row["solver"].as_str().unwrap();
        let s = &row["stats"];
        let iterations = s["iterations"].as_u64().unwrap();
        let last_sweeps = s["history"].as_array().unwrap().last().map_or(0.0, |h| h["sweeps"].as_f64().unwrap());
        assert!(last_sweeps <= 5.0 + 1e-9, "{name}: {last_sweeps} sweeps");
        if name == "progressive" {
            assert_eq!(iterations, 5 * n, "progressive: shots");
            assert_eq!(s["stop"], "max-iterations");
            assert!((last_sweeps - 5.0).abs() < 1e-9);
        } else {
            assert!(iterations <= 5, "{name}: {iterations} iterations under --max-iterations 5");
        }
        if ["jacobi", "chebyshev", "gauss-seidel", "shooting"].contains(&name) {
            assert_eq!((iterations, s["stop"].as_str().unwrap()), (5, "max-iterations"), "{name}");
        }
    }
    // The flag's help says what an iteration is for progressive.
    let help = radiosity(&dir, &["solve", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("sweeps of n shots"), "{help}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The report's `timings.stages`: every stage the progress saw, in order, with its seconds
/// — for the hierarchy its coverage, closure, links (issue 10: time per phase), for rows
/// the form factors — each within the run's total, also with `-q`.
#[test]
fn report_lists_the_time_of_every_stage() {
    let dir = tempdir("stages");
    for (transport, needs) in [("hierarchical", &["coverage", "closure", "links"][..]), ("rows", &["form factors"][..])] {
        let out = radiosity(&dir, &["solve", "cornell", "--mesh-size", "60", "--transport", transport, "-q", "--report", "r.json"]);
        assert!(out.status.success(), "{transport}: {}", String::from_utf8_lossy(&out.stderr));
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("r.json")).unwrap()).unwrap();
        let total = r["timings"]["total"].as_f64().unwrap();
        let stages = r["timings"]["stages"].as_array().expect("timings.stages");
        let names: Vec<&str> = stages.iter().map(|s| s["stage"].as_str().unwrap()).collect();
        for n in needs {
            assert!(names.contains(n), "{transport}: {names:?}");
        }
        let sum: f64 = stages.iter().map(|s| s["seconds"].as_f64().unwrap()).sum();
        assert!(stages.iter().all(|s| s["seconds"].as_f64().unwrap() >= 0.0) && sum <= total, "{transport}: stages {sum} s, total {total} s");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
