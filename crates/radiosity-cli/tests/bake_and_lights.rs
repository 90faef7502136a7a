//! `radiosity bake` and the light flags from the command line: the numbers a user reads.

use std::path::{Path, PathBuf};
use std::process::Command;

/// A folder of its own for each test: the tests run in parallel, and a shared `floor.obj`
/// rewritten by one test was read half-written by another (CI: "usemtl 'grey': no such
/// material").
fn dir(test: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-bake-lights").join(test);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// A 4 × 4 grey floor (ρ = 0.5) facing up, and nothing else.
fn floor(d: &Path) -> PathBuf {
    std::fs::write(d.join("floor.mtl"), "newmtl grey\nKd 0.5 0.5 0.5\n").unwrap();
    let p = d.join("floor.obj");
    std::fs::write(&p, "mtllib floor.mtl\nusemtl grey\no floor\nv -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\nf 1 2 3 4\n").unwrap();
    p
}

fn floor_radiance(report: &Path) -> f64 {
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(report).unwrap()).unwrap();
    r["objects"][0]["radiance_rgb"][0].as_f64().unwrap()
}

#[test]
fn sun_flag_lights_a_floor_by_its_cosine() {
    let d = dir("sun");
    let f = floor(&d);
    let report = d.join("sun.json");
    // Towards the sun at 60° from the zenith: E cos 60° = 50 on the floor, L = ρ E cos/π.
    let t = 60f64.to_radians();
    let sun = format!("{},{},0,100", t.sin(), t.cos());
    let (code, err) =
        run(&["solve", f.to_str().unwrap(), "--sun", &sun, "--sun-diameter", "0", "-q", "--report", report.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    let l = floor_radiance(&report);
    let exact = 0.5 * 100.0 * t.cos() / std::f64::consts::PI;
    assert!((l - exact).abs() < 1e-9 * exact, "floor radiance {l} against {exact}");
    // Bad values are refused before any work.
    for (args, says) in [
        (vec!["--sun", "0,0,0,1"], "must be a finite, non-zero vector"),
        (vec!["--sun", "0,1,0"], "expected X,Y,Z,E"),
        (vec!["--sun", "0,1,0,-5"], "must be finite and non-negative"),
        (vec!["--sun", "0,1,0,5", "--sun-diameter", "45"], "--sun-diameter 45 must be between 0 and 20 degrees"),
    ] {
        let mut a = vec!["solve", f.to_str().unwrap(), "-q"];
        a.extend(args);
        let (code, err) = run(&a);
        assert!(code == Some(1) || code == Some(2), "{a:?}: exit {code:?}");
        assert!(err.contains(says), "{a:?}: {err}");
    }
}

#[test]
fn bake_writes_a_glb_and_refuses_what_it_cannot_write() {
    let d = dir("bake");
    let glb = d.join("cornell.glb");
    let (code, err) = run(&["bake", "-o", glb.to_str().unwrap(), "--mesh-size", "100", "--exposure", "2"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("at exposure 2.0000e0"), "{err}");
    let bytes = std::fs::read(&glb).unwrap();
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize, bytes.len());
    for (args, says) in [
        (vec!["bake", "-o", "x.png"], "name the file .glb"),
        (vec!["bake", "-o", "x.glb", "--exposure=0"], "--exposure must be a positive number"),
    ] {
        let (code, err) = run(&args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    // A scene without a camera (an OBJ) gets the view `render` would frame, as a glTF camera.
    let floor_glb = d.join("floor.glb");
    let (code, err) = run(&["bake", floor(&d).to_str().unwrap(), "--sky", "1", "-q", "-o", floor_glb.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    let b = std::fs::read(&floor_glb).unwrap();
    let n = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&b[20..20 + n]).unwrap();
    assert_eq!(doc["cameras"].as_array().map(|c| c.len()), Some(1), "no camera in the baked OBJ");
    // An output under a file (not a folder) is refused before any work.
    let under = floor(&d).join("x.glb");
    let (code, err) = run(&["bake", "-o", under.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("is not a folder") && !err.contains("iteration"), "{err}");
}

/// `--sky-image FILE --sky-strength K --sky-rotation DEG`: a floor alone under a constant
/// image of radiance 0.5 at strength 2 reflects ρ·0.5·2 = 0.5; the flags that need an image
/// or exclude one are refused before any work.
#[test]
fn sky_image_flag_lights_a_floor_and_refuses_conflicts() {
    let d = dir("sky-image");
    let f = floor(&d);
    let mut img = radiosity::render::Image::new(16, 8);
    img.pixels.iter_mut().for_each(|p| *p = radiosity::Rgb::splat(0.5));
    let exr = d.join("const.exr");
    std::fs::write(&exr, radiosity::output::exr::encode(&img).unwrap()).unwrap();
    let report = d.join("image.json");
    let (code, err) = run(&[
        "solve",
        f.to_str().unwrap(),
        "--sky-image",
        exr.to_str().unwrap(),
        "--sky-strength",
        "2",
        "--sky-rotation",
        "-30",
        "-q",
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let l = floor_radiance(&report);
    assert!((l - 0.5).abs() < 1e-6, "floor radiance {l}");
    let (code, err) = run(&["solve", f.to_str().unwrap(), "--sky", "1", "--sky-image", exr.to_str().unwrap(), "-q"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("not both"), "{err}");
    let (code, err) = run(&["solve", f.to_str().unwrap(), "--sky", "1", "--sky-rotation", "10", "-q"]);
    assert!(code == Some(1) && err.contains("need --sky-image"), "{err}");
}
