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

#[test]
fn sigint_during_rendering_many_views_stops_promptly_with_code_130() {
    use std::time::{Duration, Instant};
    let dir = tempdir("render-views");
    // 40 large final-gather views: minutes of rendering if the interrupt were ignored.
    let views: Vec<String> = (0..40)
        .map(|k| {
            let x = 200 + 4 * k;
            format!(r#"{{"name": "v{k}", "position": [{x}, 273, -800], "look_at": [278, 273, 280], "up": [0, 1, 0], "vfov_deg": 40}}"#)
        })
        .collect();
    std::fs::write(dir.join("views.json"), format!("[{}]", views.join(","))).unwrap();
    let args = ["render", "cornell", "--mesh-size", "110", "--views", "views.json", "-o", "shots/v.png", "--report", "r.json"];
    let mut child = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(args)
        .args(["--width", "512", "--height", "512", "--spp", "8"])
        .current_dir(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the program starts");
    let reader = BufReader::new(child.stderr.take().unwrap());
    let mut log = String::new();
    let mut sent: Option<Instant> = None;
    for line in reader.lines() {
        let line = line.unwrap();
        // The solve is done once the energy summary prints; rendering starts at once.
        if line.starts_with("energy:") && sent.is_none() {
            std::thread::sleep(Duration::from_millis(700));
            assert!(Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
            sent = Some(Instant::now());
        }
        log.push_str(&line);
        log.push('\n');
    }
    let status = child.wait().unwrap();
    let sent = sent.unwrap_or_else(|| panic!("the render never started:\n{log}"));
    let after = sent.elapsed().as_secs_f64();
    assert_eq!(status.code(), Some(130), "{log}");
    assert!(after < 15.0, "ran on {after:.1} s after the interrupt:\n{log}");
    assert!(!log.contains("panicked"), "{log}");
    assert!(log.contains("interrupted while rendering view"), "{log}");
    // The report lists the views finished before the interrupt; each of their images is
    // complete, and no other image (nor a temporary file) was written.
    let r = report(&dir.join("r.json"));
    let done: Vec<String> = r["views"].as_array().unwrap().iter().map(|v| v["name"].as_str().unwrap().to_string()).collect();
    assert!(done.len() < 40, "{log}");
    let written: Vec<String> = match std::fs::read_dir(dir.join("shots")) {
        Ok(rd) => rd.map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect(),
        Err(_) => Vec::new(),
    };
    assert_eq!(written.len(), done.len(), "written {written:?}, reported {done:?}");
    for name in &done {
        assert!(is_png(&dir.join(format!("shots/v_{name}.png"))), "{name}");
    }
    assert!(r["warnings"].as_array().unwrap().iter().any(|w| w.as_str().unwrap().contains("interrupted while rendering")));
    let _ = std::fs::remove_dir_all(&dir);
}
