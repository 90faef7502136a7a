//! Issue 4: an interrupted run (SIGINT during the solve) exits cleanly with code 130 and
//! leaves valid output files: the report, the image, the EXR and the frames so far.
#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};

/// Runs the program in `dir`, sends SIGINT once stderr shows `lines` solver iterations,
/// and returns the exit code and everything it printed on stderr.
fn interrupt_after(dir: &Path, args: &[&str], lines: usize) -> (Option<i32>, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the program starts");
    let reader = BufReader::new(child.stderr.take().unwrap());
    let mut seen = 0;
    let mut sent = false;
    let mut log = String::new();
    for line in reader.lines() {
        let line = line.unwrap();
        if line.contains(" iteration ") {
            seen += 1;
        }
        if seen >= lines && !sent {
            let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
            assert!(status.success());
            sent = true;
        }
        log.push_str(&line);
        log.push('\n');
    }
    let status = child.wait().unwrap();
    assert!(sent, "the solve never started:\n{log}");
    (status.code(), log)
}

fn tempdir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("radiosity-interrupt-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn is_png(path: &Path) -> bool {
    let b = std::fs::read(path).unwrap();
    b.len() > 60 && b.starts_with(b"\x89PNG\r\n\x1a\n") && b[b.len() - 8..b.len() - 4] == *b"IEND"
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).expect("the report is valid JSON")
}

/// Never converges by itself: tolerance 0 and no iteration cap to speak of (the time
/// budget only guards against a broken signal handler).
const FOREVER: [&str; 6] = ["--tolerance", "0", "--max-iterations", "100000000", "--time-budget", "120"];

#[test]
fn sigint_during_render_keeps_the_solution_so_far_and_writes_every_output() {
    let dir = tempdir("render");
    let mut args = vec!["render", "cornell", "--mesh-size", "110", "--solver", "jacobi", "--width", "48", "--height", "48"];
    args.extend(["--spp", "1", "-o", "out.png", "--exr", "out.exr", "--report", "r.json", "--frames", "frames"]);
    args.extend(FOREVER);
    let (code, log) = interrupt_after(&dir, &args, 5);
    assert_eq!(code, Some(130), "{log}");
    assert!(!log.contains("panicked"), "{log}");
    let r = report(&dir.join("r.json"));
    assert_eq!(r["solver"]["stop"], "interrupted");
    assert!(r["solver"]["iterations"].as_u64().unwrap() >= 5);
    assert!(r["residual"].as_f64().unwrap() < 0.1);
    assert!(is_png(&dir.join("out.png")));
    let exr = radiosity::output::exr::read(&dir.join("out.exr")).expect("the EXR reads back");
    assert_eq!((exr.width, exr.height), (48, 48));
    assert!(exr.pixels.iter().any(|p| p.x > 0.0));
    assert!(is_png(&dir.join("frames/frame-0001.png")));
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("frames/frames.json")).unwrap()).unwrap();
    assert!(index["frames"].as_array().unwrap().len() >= 5);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigint_during_a_stochastic_solve_writes_the_report() {
    let dir = tempdir("stochastic");
    // Enough rays that the interrupt arrives in the middle of the second iteration.
    let mut args = vec!["solve", "cornell", "--mesh-size", "110", "--solver", "stochastic-shooting", "--rays", "8000000"];
    args.extend(["--report", "r.json"]);
    args.extend(FOREVER);
    let (code, log) = interrupt_after(&dir, &args, 1);
    assert_eq!(code, Some(130), "{log}");
    assert!(!log.contains("panicked"), "{log}");
    let r = report(&dir.join("r.json"));
    assert_eq!(r["solver"]["stop"], "interrupted");
    // The interrupted iteration is dropped whole: the report holds complete iterations.
    assert_eq!(r["solver"]["iterations"], r["solver"]["history"].as_array().unwrap().len());
    assert!(r["solver"]["rays"].as_u64().unwrap() >= 8_000_000);
    assert!(r["solver"]["error_estimate"].as_f64().unwrap() > 0.0);
    assert!(r["energy"]["imbalance"].as_f64().unwrap() < 1e-9);
    let _ = std::fs::remove_dir_all(&dir);
}
