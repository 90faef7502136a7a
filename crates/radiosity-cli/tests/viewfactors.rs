//! `radiosity viewfactors`: every output format, a View3D input, the enclosure flag, the
//! comparison with a reference, and clear errors.

use std::path::{Path, PathBuf};
use std::process::Command;

fn run(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into())
}

fn data(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../radiosity/tests/data").join(name).to_string_lossy().into()
}

/// A file in this target's own scratch folder (under target/, not left in the system's
/// temporary folder after every run).
fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("viewfactors");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn parallel_planes_in_every_format() {
    let exact = 0.199824895698;
    let scene = data("ParallelPlanes.vs3");
    let json = tmp("pp.json");
    let (code, err) = run(&["viewfactors", &scene, "--method", "analytic", "-o", json.to_str().unwrap(), "--quiet"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["names"][1], "top");
    assert!((v["matrix"][0][1].as_f64().unwrap() - exact).abs() < 1e-12);
    assert!(v["diagnostics"]["reciprocity_max_rel"].as_f64().unwrap() < 1e-12);

    let csv = tmp("pp.csv");
    assert_eq!(run(&["viewfactors", &scene, "--method", "analytic", "-o", csv.to_str().unwrap(), "-q"]).0, 0);
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "surface,area,bottom,top");
    let f: f64 = lines[1].split(',').nth(3).unwrap().parse().unwrap();
    assert!((f - exact).abs() < 1e-12);

    let npy = tmp("pp.npy");
    assert_eq!(run(&["viewfactors", &scene, "--method", "analytic", "-o", npy.to_str().unwrap(), "-q"]).0, 0);
    let b = std::fs::read(&npy).unwrap();
    let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
    let f = f64::from_le_bytes(b[10 + hl + 8..10 + hl + 16].try_into().unwrap());
    assert!((f - exact).abs() < 1e-12);

    let vf = tmp("pp.vf");
    assert_eq!(run(&["viewfactors", &scene, "--method", "analytic", "-o", vf.to_str().unwrap(), "-q"]).0, 0);
    let text = std::fs::read_to_string(&vf).unwrap();
    assert_eq!(text.lines().nth(2).unwrap(), "0.000000 0.199825");
}

#[test]
fn box345_enclosure_from_the_file_and_per_element_streaming() {
    let scene = data("box345.vs3");
    let out = tmp("box.json");
    let report = tmp("box-report.json");
    let (code, err) = run(&[
        "viewfactors", &scene, "--method", "monte-carlo", "--mesh-size", "0", "--mc-rays", "1024",
        "-o", out.to_str().unwrap(), "--report", report.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("encl=1"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(v["diagnostics"]["reciprocity_max_rel"].as_f64().unwrap() <= 1e-6);
    assert!(v["diagnostics"]["closure_max_error"].as_f64().unwrap() <= 1e-9);
    assert!(v["enclosure"]["max_change"].as_f64().unwrap() > 0.0);
    // A memory limit below the dense matrix streams per-element rows instead.
    let npy = tmp("box.npy");
    let (code, err) = run(&[
        "viewfactors", &scene, "--method", "monte-carlo", "--mc-rays", "16", "--per", "element", "--mesh-size", "0",
        "--no-enclosure", "--memory-limit", "10K", "-o", npy.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("streamed"), "{err}");
    assert_eq!(std::fs::metadata(&npy).unwrap().len(), 128 + 106 * 106 * 8);
    // ... but the enclosure correction needs the whole matrix: a clear error with the size.
    let (code, err) =
        run(&["viewfactors", &scene, "--per", "element", "--mesh-size", "0", "--memory-limit", "10K", "-o", npy.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("would need 87.8 KiB"), "{err}");
}

#[test]
fn cornell_comparison_with_the_reference() {
    let out = tmp("cornell.json");
    let report = tmp("cornell-report.json");
    let (code, err) = run(&[
        "viewfactors", "cornell", "--method", "adaptive", "-o", out.to_str().unwrap(),
        "--compare", &data("cornell_view_factors_monte_carlo.json"), "--report", report.to_str().unwrap(), "-q",
    ]);
    assert_eq!(code, 0, "{err}");
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert!(r["comparison"]["max_abs_error"].as_f64().unwrap() <= 1e-3, "{}", r["comparison"]);
    assert!(r["comparison"]["max_abs_error_per_row"]["floor"].as_f64().unwrap() <= 1e-3);
}

#[test]
fn bad_requests_are_clear_errors() {
    let o = tmp("x.xyz");
    let (code, err) = run(&["viewfactors", "cornell", "-o", o.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("cannot tell the format"), "{err}");
    let o = tmp("x.csv");
    let (code, err) = run(&["viewfactors", "cornell", "--method", "radiance", "-o", o.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("unknown form-factor method 'radiance'"), "{err}");
    // The Cornell box is open: closure cannot be enforced.
    let (code, err) = run(&["viewfactors", "cornell", "--enclosure", "-o", o.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("not an enclosure"), "{err}");
    assert!(!o.exists(), "no output is written on error");
}

#[test]
fn emit_1_writes_view3d_emittance_weighted_factors_that_viewht_reads() {
    // box345 with emit=1: rows of ℱ = εB sum to ε in the (corrected) enclosure.
    let text = std::fs::read_to_string(data("box345.vs3")).unwrap().replace("emit=0", "emit=1");
    let scene = tmp("box345-emit.vs3");
    std::fs::write(&scene, text).unwrap();
    let vf = tmp("box345-emit.vf");
    let (code, err) = run(&["viewfactors", scene.to_str().unwrap(), "-o", vf.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("emittance-weighted"), "{err}");
    let text = std::fs::read_to_string(&vf).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split_whitespace().collect();
    assert_eq!(&header[2..5], &["0", "1", "1"], "format encl didemit");
    let n: usize = header[5].parse().unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let eps: Vec<f64> = lines[2 + n].split_whitespace().map(|w| w.parse().unwrap()).collect();
    for i in 0..n {
        let sum: f64 = lines[2 + i].split_whitespace().map(|w| w.parse::<f64>().unwrap()).sum();
        assert!((sum - eps[i]).abs() < 5e-6 * n as f64, "row {i}: Σℱ = {sum}, ε = {}", eps[i]);
    }
    // The same file through ViewHT's table: surfaces 1–10 hotter, the rest at 300 K.
    let temps = tmp("box345-temps.txt");
    std::fs::write(&temps, "1 999 300\n1 10 350\n0 0\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .args(["thermal", vf.to_str().unwrap(), "--temperatures", temps.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The balance closes to the file's six decimals.
    let rel: f64 = stdout.split(" W (").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    assert!(rel < 1e-5, "{stdout}");
    // --no-emittances writes plain F.
    let (code, err) =
        run(&["viewfactors", scene.to_str().unwrap(), "--method", "analytic", "--no-emittances", "-o", vf.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read_to_string(&vf).unwrap().lines().next().unwrap().split_whitespace().nth(4), Some("0"));
}

/// (n, row sums, A_i F_ij by (i, j)) of a Matrix Market file with areas in its comments.
fn read_mtx(path: &Path) -> (usize, Vec<f64>, std::collections::HashMap<(usize, usize), f64>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut areas = Vec::new();
    let mut entries = Vec::new();
    let mut n = 0;
    for line in text.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        if line.starts_with('%') {
            if w.len() > 3 && w[2] == "area" {
                areas.push(w[3].parse::<f64>().unwrap());
            }
        } else if n == 0 {
            n = w[0].parse().unwrap();
        } else {
            entries.push((w[0].parse::<usize>().unwrap() - 1, w[1].parse::<usize>().unwrap() - 1, w[2].parse::<f64>().unwrap()));
        }
    }
    let mut sums = vec![0.0; n];
    let mut af = std::collections::HashMap::new();
    for (i, j, f) in entries {
        sums[i] += f;
        af.insert((i, j), areas[i] * f);
    }
    (n, sums, af)
}

#[test]
fn sparse_output_keeps_row_sums_and_reciprocity() {
    let scene = data("box345.vs3");
    // Dense reference: row sums.
    let dense = tmp("box-dense.json");
    assert_eq!(run(&["viewfactors", &scene, "-o", dense.to_str().unwrap(), "-q"]).0, 0);
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&dense).unwrap()).unwrap();
    let rows: Vec<f64> =
        v["matrix"].as_array().unwrap().iter().map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).sum()).collect();
    let nonzero: usize = v["matrix"].as_array().unwrap().iter().map(|r| r.as_array().unwrap().iter().filter(|x| x.as_f64().unwrap() > 0.0).count()).sum();
    let mtx = tmp("box.mtx");
    let (code, err) = run(&["viewfactors", &scene, "-o", mtx.to_str().unwrap(), "--sparse-threshold", "0.01"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("sparse:"), "{err}");
    let (n, sums, af) = read_mtx(&mtx);
    assert_eq!(n, rows.len());
    assert!(af.len() < nonzero / 2, "kept {} of {nonzero}", af.len());
    for i in 0..n {
        assert!((sums[i] - rows[i]).abs() < 1e-9, "row {i}: {} vs {}", sums[i], rows[i]);
    }
    for (&(i, j), &x) in &af {
        let y = af.get(&(j, i)).copied().unwrap_or(0.0);
        assert!((x - y).abs() <= 1e-6 * x.max(y), "A F [{i}][{j}] {x} vs {y}");
    }
    // Streamed per element (the matrix never held dense) into CSV triplets.
    let csv = tmp("pp-elements.csv");
    let (code, err) = run(&[
        "viewfactors", &data("ParallelPlanes.vs3"), "--per", "element", "--mesh-size", "0.2", "--method", "point-sampled",
        "--memory-limit", "1K", "--sparse-threshold", "1e-3", "-o", csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("streamed") && err.contains("sparse:"), "{err}");
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.starts_with("row,column,row_name,column_name,value\n") && text.lines().count() > 100);
    // Formats that cannot hold a sparse matrix are refused before any work.
    let (code, err) = run(&["viewfactors", &scene, "-o", tmp("x.npy").to_str().unwrap(), "--sparse-threshold", "0.01"]);
    assert_ne!(code, 0);
    assert!(err.contains(".mtx"), "{err}");
}

/// `radiosity thermal` with per-band emissivities (scenes/thermal-selective.toml: two
/// bands split at 4 µm by the scene's `[thermal] band_edges`): the JSON carries the edges
/// and each surface's heat per band, which add up to its heat; the enclosure balances.
/// `--bands` overrides the scene's edges and is checked before any work.
#[test]
fn thermal_in_bands_from_a_scene_and_the_command_line() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/thermal-selective.toml");
    let scene = scene.to_str().unwrap();
    let json = tmp("selective.json");
    let (code, err) = run(&["thermal", scene, "--enclosure", "--mesh-size", "0.25", "--json", json.to_str().unwrap(), "-q"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["band_edges_um"], serde_json::json!([4.0]));
    let total = v["total_W"].as_f64().unwrap();
    assert!(v["balance_W"].as_f64().unwrap().abs() <= 1e-9 * total, "{v}");
    for s in v["surfaces"].as_array().unwrap() {
        let bands: Vec<f64> = s["band_heat"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        assert_eq!(bands.len(), 2);
        let heat = s["heat"].as_f64().unwrap();
        assert!((bands.iter().sum::<f64>() - heat).abs() <= 1e-9 * total, "{s}");
    }
    // The re-radiating walls take in short waves and give out long ones.
    let walls = v["surfaces"].as_array().unwrap().iter().find(|s| s["name"] == "walls").unwrap();
    assert!(walls["band_heat"][0].as_f64().unwrap() < 0.0 && walls["band_heat"][1].as_f64().unwrap() > 0.0, "{walls}");
    // Three bands for two emissivities; edges that go down; grey while materials have bands.
    let (code, err) = run(&["thermal", scene, "--bands", "2,4", "-q"]);
    assert!(code != 0 && err.contains("2 band emissivities for 3 band(s)"), "{err}");
    let (code, err) = run(&["thermal", scene, "--bands", "4,2", "-q"]);
    assert!(code != 0 && err.contains("--bands: band edges must increase"), "{err}");
    let (code, err) = run(&["thermal", scene, "--bands", "none", "-q"]);
    assert!(code != 0 && err.contains("no band edges"), "{err}");
}

/// A form-factor warning prints once, under `--quiet` too, and is kept in the report: the
/// warnings print as they arise and were printed a second time at the end.
#[test]
fn a_warning_prints_once_and_is_kept_in_the_report() {
    let (out, report) = (tmp("cornell-analytic.csv"), tmp("cornell-analytic.json"));
    let (code, err) = run(&[
        "viewfactors",
        "cornell",
        "--method",
        "analytic",
        "-o",
        out.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{err}");
    let occlusion = "analytic form factors ignore occlusion";
    assert_eq!(err.matches(occlusion).count(), 1, "{err}");
    assert_eq!(err.matches("summed above 1 and were scaled").count(), 1, "{err}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let kept = v["form_factors"]["warnings"].as_array().unwrap();
    assert!(kept.iter().any(|w| w.as_str().unwrap().contains(occlusion)), "{kept:?}");
}
