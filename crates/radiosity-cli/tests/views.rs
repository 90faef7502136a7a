//! `radiosity render --views`: several cameras from one solve.

use std::process::Command;

#[test]
fn views_render_from_one_solve_with_per_view_cost() {
    let dir = std::env::temp_dir().join(format!("radiosity-views-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let views = r#"[
        {"name": "front", "position": [278, 273, -800], "look_at": [278, 273, 0], "up": [0, 1, 0], "vfov_deg": 39.3},
        {"name": "side", "position": [400, 300, -600], "look_at": [278, 273, 280], "up": [0, 1, 0], "vfov_deg": 45}
    ]"#;
    std::fs::write(dir.join("views.json"), views).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .current_dir(&dir)
        .args(["render", "--views", "views.json", "-o", "shots/cb.png", "--exr", "shots/cb.exr", "--render", "gouraud"])
        .args(["--width", "64", "--height", "64", "--mesh-size", "80", "--report", "r.json", "-q"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("r.json")).unwrap()).unwrap();
    let v = r["views"].as_array().unwrap();
    assert_eq!(v.len(), 2);
    assert_eq!(v[0]["name"], "front");
    assert_eq!(v[1]["name"], "side");
    for (view, name) in v.iter().zip(["front", "side"]) {
        assert!(view["seconds"].as_f64().unwrap() > 0.0);
        for f in [format!("shots/cb_{name}.png"), format!("shots/cb_{name}.exr")] {
            assert!(dir.join(&f).exists(), "{f} missing");
        }
    }
    // One solve: one solver record, and the two images differ (different cameras).
    assert!(r["solver"]["iterations"].as_u64().unwrap() > 0);
    let a = std::fs::read(dir.join("shots/cb_front.exr")).unwrap();
    let b = std::fs::read(dir.join("shots/cb_side.exr")).unwrap();
    assert_ne!(a, b);
    // A bad view list is a clear error naming the file.
    std::fs::write(dir.join("bad.json"), r#"[{"name": "x", "position": [0,0,0], "look_at": [0,0,0], "up": [0,1,0], "vfov_deg": 40}]"#).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity"))
        .current_dir(&dir)
        .args(["render", "--views", "bad.json", "-q"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.json") && err.contains("coincide"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
