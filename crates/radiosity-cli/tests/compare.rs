//! `radiosity compare` on images with a known error.

use std::path::Path;
use std::process::Command;

use radiosity::output::exr;
use radiosity::render::Image;
use radiosity::Rgb;

fn write(path: &Path, img: &Image) {
    std::fs::write(path, exr::encode(img).unwrap()).unwrap();
}

fn run(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

#[test]
fn compare_reports_relative_rmse_and_masks_the_light() {
    let dir = std::env::temp_dir().join(format!("radiosity-compare-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Reference: 0.5 everywhere, a 2×2 "light" of 10 in the middle of a 10×10 image.
    let mut reference = Image::new(10, 10);
    for (k, p) in reference.pixels.iter_mut().enumerate() {
        let (x, y) = (k % 10, k / 10);
        *p = if (4..6).contains(&x) && (4..6).contains(&y) { Rgb::splat(10.0) } else { Rgb::splat(0.5) };
    }
    // Image: every pixel 10 % too bright, and the light wrong by a lot.
    let mut img = reference.clone();
    for p in img.pixels.iter_mut() {
        *p = if p.x > 1.0 { Rgb::splat(20.0) } else { *p * 1.1 };
    }
    let (a, b) = (dir.join("img.exr"), dir.join("ref.exr"));
    write(&a, &img);
    write(&b, &reference);
    let heat = dir.join("heat.png");
    let (code, stdout, stderr) =
        run(&["compare", a.to_str().unwrap(), b.to_str().unwrap(), "--json", "--heatmap", heat.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    // Masked: the 2×2 light and its ring (4×4 pixels) excluded; the rest is exactly 10 % off.
    let masked = j["relative_rmse_light_masked"].as_f64().unwrap();
    assert!((masked - 0.1).abs() < 1e-6, "{masked}");
    // All pixels: sqrt((96·0.05² + 4·10²)/100) / ((96·0.5 + 4·10)/100).
    let expect = ((96.0 * 0.05f64.powi(2) + 4.0 * 100.0) / 100.0).sqrt() / ((96.0 * 0.5 + 4.0 * 10.0) / 100.0);
    let all = j["relative_rmse"].as_f64().unwrap();
    assert!((all - expect).abs() < 1e-6 * expect, "{all} vs {expect}");
    assert!(std::fs::metadata(&heat).unwrap().len() > 50);
    // Identical images: zero.
    let (code, stdout, _) = run(&["compare", b.to_str().unwrap(), b.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0);
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["relative_rmse"].as_f64().unwrap(), 0.0);
    // Different sizes and missing files are clear errors, not panics.
    let mut small = Image::new(5, 5);
    small.pixels.iter_mut().for_each(|p| *p = Rgb::ONE);
    let c = dir.join("small.exr");
    write(&c, &small);
    let (code, _, stderr) = run(&["compare", c.to_str().unwrap(), b.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(stderr.contains("sizes differ"), "{stderr}");
    let (code, _, stderr) = run(&["compare", dir.join("nope.exr").to_str().unwrap(), b.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(stderr.contains("nope.exr"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}
