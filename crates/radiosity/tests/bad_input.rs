//! Malformed OBJ/MTL and camera JSON: every case is an `Err` naming the file (and the line,
//! where the format has lines) or, for degenerate polygons, a warning and a skip — never a
//! panic. Property tests feed random bytes and random OBJ-like lines to the parsers.
//! (glTF and TOML have the same kind of tests in `gltf.rs` and `toml_scene.rs`.)

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use radiosity::scene::{self, obj, Camera, Scene};

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bad-input");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn write(name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = tmp(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

const MTL: &str = "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n";

/// Writes `good.mtl` once (tests run in parallel and read it).
fn write_good_mtl() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        write("good.mtl", MTL);
    });
}

/// Loads and validates `name` (an OBJ written with `text`, next to a good `good.mtl`).
fn load(name: &str, text: &str) -> radiosity::Result<Scene> {
    write_good_mtl();
    let p = write(name, text);
    Scene::from_desc(scene::load(p.to_str().unwrap())?)
}

/// Asserts loading fails with an error that starts with `<file>:<line>:`.
fn fails_at(name: &str, text: &str, file: &str, line: usize) -> String {
    let e = match load(name, text) {
        Ok(_) => panic!("{name} loaded but should not"),
        Err(e) => e.to_string(),
    };
    let want = format!("{}:{line}:", tmp(file).display());
    assert!(e.starts_with(&want), "{name}: expected {want}…, got: {e}");
    e
}

const QUAD: &str = "mtllib good.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl grey\n";

#[test]
fn obj_numbers_that_are_not_finite() {
    fails_at("nan.obj", "v 0 0 0\nv nan 0 0\n", "nan.obj", 2);
    fails_at("inf.obj", "v 0 0 0\nv 0 inf 0\n", "inf.obj", 2);
    fails_at("big.obj", "v 0 0 1e999\n", "big.obj", 1);
    fails_at("word.obj", "v 0 zero 0\n", "word.obj", 1);
    fails_at("short.obj", "v 0 0\n", "short.obj", 1);
}

#[test]
fn obj_indices_out_of_range() {
    for (i, f) in ["f 1 2 5", "f 0 1 2", "f -5 1 2", "f 1 2 99999999999999999999", "f 1/1 2/2 x", "f a b c"].iter().enumerate() {
        fails_at(&format!("idx{i}.obj"), &format!("{QUAD}{f}\n"), &format!("idx{i}.obj"), 7);
    }
    fails_at("two.obj", &format!("{QUAD}f 1 2\n"), "two.obj", 7);
}

#[test]
fn obj_materials_missing_or_unphysical() {
    fails_at("nomtl.obj", "mtllib nowhere.mtl\nv 0 0 0\n", "nomtl.obj", 1);
    fails_at("usemtl.obj", "mtllib good.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl chrome\nf 1 2 3\n", "usemtl.obj", 5);
    for (name, mtl, line) in [
        ("kd1.mtl", "newmtl a\nKd 1 0.5 0.5\n", 2),
        ("kdnan.mtl", "newmtl a\nKd nan\n", 2),
        ("kdneg.mtl", "# c\nnewmtl a\nKd -0.1 0.5 0.5\n", 3),
        ("keneg.mtl", "newmtl a\nKd 0.5 0.5 0.5\nKe 1 -1 1\n", 3),
        ("keinf.mtl", "newmtl a\nKe inf 1 1\n", 2),
        ("kdtwo.mtl", "newmtl a\nKd 0.5 0.5\n", 2),
        ("early.mtl", "Kd 0.5 0.5 0.5\n", 1),
        ("spectral.mtl", "newmtl a\nKd spectral x.spd\n", 2),
        ("noname.mtl", "newmtl\n", 1),
    ] {
        write(name, mtl);
        let obj = format!("mtllib {name}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n");
        fails_at(&format!("{name}.obj"), &obj, name, line);
    }
}

#[test]
fn obj_empty_garbage_and_missing_files() {
    let e = load("empty.obj", "").unwrap_err().to_string();
    assert!(e.contains("empty.obj") && e.contains("no faces"), "{e}");
    let e = load("comments.obj", "# nothing\n\n   \n").unwrap_err().to_string();
    assert!(e.contains("comments.obj"), "{e}");
    let garbage: Vec<u8> = (0..4096u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
    let p = write("garbage.obj", &garbage);
    let e = scene::load(p.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("garbage.obj"), "{e}");
    let e = scene::load(tmp("does-not-exist.obj").to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("does-not-exist.obj"), "{e}");
    // Latin-1 bytes in comments and names are read (lossily), not rejected.
    let mut latin = b"# caf\xe9\n".to_vec();
    latin.extend(QUAD.as_bytes());
    latin.extend(b"o caf\xe9\nf 1 2 3 4\n");
    write_good_mtl();
    let p = write("latin1.obj", &latin);
    assert_eq!(Scene::from_desc(scene::load(p.to_str().unwrap()).unwrap()).unwrap().polygons.len(), 1);
}

#[test]
fn obj_truncated_anywhere_never_panics_and_errors_name_a_line() {
    let text = include_str!("../data/cornell/cornell_box.obj");
    let mtl = include_str!("../data/cornell/cornell_box.mtl");
    let file = Path::new("cut.obj");
    for n in (0..text.len()).step_by(37) {
        let Some(cut) = text.get(..n) else { continue };
        let r = obj::parse_obj(cut, file, |_, _| obj::parse_mtl(mtl, Path::new("cut.mtl")));
        match r {
            Ok(d) => {
                let _ = Scene::from_desc(d);
            }
            Err(e) => {
                let s = e.to_string();
                assert!(s.starts_with("cut.obj"), "{s}");
            }
        }
    }
    for n in (0..mtl.len()).step_by(5) {
        let Some(cut) = mtl.get(..n) else { continue };
        if let Err(e) = obj::parse_mtl(cut, Path::new("cut.mtl")) {
            assert!(e.to_string().starts_with("cut.mtl:"), "{e}");
        }
    }
}

#[test]
fn degenerate_polygons_are_skipped_with_a_warning_naming_the_line() {
    let text = format!("{QUAD}f 1 2 3 4\nf 1 2 2\nf 1 1 1\nv 2 0 0\nf 1 2 5\n");
    let s = load("degenerate.obj", &text).unwrap();
    assert_eq!(s.polygons.len(), 1);
    let w: Vec<String> = s.warnings.iter().map(|w| w.to_string()).collect();
    let p = tmp("degenerate.obj").display().to_string();
    for line in [8, 9, 11] {
        assert!(w.iter().any(|x| x.starts_with(&format!("{p}:{line}:"))), "line {line}: {w:?}");
    }
    // Only degenerate faces: an error, not an empty scene.
    let e = load("alldegenerate.obj", &format!("{QUAD}f 1 1 2\n")).unwrap_err().to_string();
    assert!(e.contains("alldegenerate") && e.contains("no usable polygons"), "{e}");
}

// ---------------------------------------------------------------- camera JSON

fn camera_err(name: &str, text: &str) -> String {
    let p = write(name, text);
    match Camera::load_json(&p) {
        Ok(c) => panic!("{name} loaded: {c:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn camera_json_errors_name_file_and_line() {
    let p = |n: &str| tmp(n).display().to_string();
    let good = "{\n  \"position\": [0, 0, -5],\n  \"look_at\": [0, 0, 0],\n  \"up\": [0, 1, 0],\n  \"vfov_deg\": 40\n}\n";
    Camera::load_json(&write("good.json", good)).unwrap();
    for (name, text, line) in [
        ("trunc.json", &good[..40], 3),
        ("garbage.json", "\u{1}\u{2}garbage", 1),
        ("empty.json", "", 1),
        ("types.json", "{\n \"position\": \"here\"\n}", 2),
        ("nan.json", "{\n \"position\": [NaN, 0, 0]\n}", 2),
        ("huge.json", "{\n \"position\": [1e999, 0, 0]\n}", 2),
        ("missing.json", "{\n \"position\": [0, 0, 0]\n}", 3),
        ("fov.json", &good.replace("40", "180"), 5),
        ("fov0.json", &good.replace("40", "0"), 5),
        ("same.json", &good.replace("[0, 0, 0]", "[0, 0, -5]"), 3),
        ("up.json", &good.replace("[0, 1, 0]", "[0, 0, 1]"), 4),
    ] {
        let e = camera_err(name, text);
        assert!(e.starts_with(&format!("{}:{line}:", p(name))), "{name}: {e}");
    }
    let e = Camera::load_json(&tmp("absent.json")).unwrap_err().to_string();
    assert!(e.contains("absent.json"), "{e}");
}

// ---------------------------------------------------------------- property tests

/// Lines that look like OBJ: keywords with random numbers and indices.
fn obj_line() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        (-1e3f64..1e3).prop_map(|x| x.to_string()),
        Just("nan".to_string()),
        Just("1e400".to_string()),
        Just("-0".to_string()),
        Just("x".to_string()),
    ];
    let idx = prop_oneof![(-12i64..12).prop_map(|i| i.to_string()), (-12i64..12, 0i64..5).prop_map(|(a, b)| format!("{a}/{b}/{a}")), Just("//".to_string())];
    prop_oneof![
        proptest::collection::vec(num, 0..5).prop_map(|v| format!("v {}", v.join(" "))),
        proptest::collection::vec(idx, 0..7).prop_map(|v| format!("f {}", v.join(" "))),
        Just("usemtl grey".to_string()),
        Just("usemtl nope".to_string()),
        Just("mtllib any.mtl".to_string()),
        Just("o thing".to_string()),
        Just("g".to_string()),
        Just("l 1 2".to_string()),
        Just("# comment \\".to_string()),
        Just("\\".to_string()),
        proptest::collection::vec(any::<char>(), 0..20).prop_map(|c| c.into_iter().collect()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn obj_parser_never_panics_on_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let text = String::from_utf8_lossy(&bytes);
        let r = obj::parse_obj(&text, Path::new("r.obj"), |_, _| obj::parse_mtl(&text, Path::new("r.mtl")));
        if let Ok(d) = r {
            let _ = Scene::from_desc(d);
        }
    }

    #[test]
    fn obj_parser_never_panics_on_obj_like_lines(lines in proptest::collection::vec(obj_line(), 0..40)) {
        let text = lines.join("\n");
        let r = obj::parse_obj(&text, Path::new("r.obj"), |_, _| obj::parse_mtl(MTL, Path::new("r.mtl")));
        match r {
            Ok(d) => { let _ = Scene::from_desc(d); }
            Err(e) => prop_assert!(e.to_string().starts_with("r.obj"), "{}", e),
        }
    }

    #[test]
    fn mtl_parser_never_panics(lines in proptest::collection::vec(
        prop_oneof![
            Just("newmtl a".to_string()),
            (0usize..4, -2f64..2.0).prop_map(|(n, x)| format!("Kd {}", vec![x.to_string(); n].join(" "))),
            (0usize..4, -2f64..20.0).prop_map(|(n, x)| format!("Ke {}", vec![x.to_string(); n].join(" "))),
            proptest::collection::vec(any::<char>(), 0..12).prop_map(|c| c.into_iter().collect::<String>()),
        ], 0..12)) {
        if let Err(e) = obj::parse_mtl(&lines.join("\n"), Path::new("r.mtl")) {
            prop_assert!(e.to_string().starts_with("r.mtl:"), "{}", e);
        }
    }

    #[test]
    fn camera_json_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = Camera::from_json_str(&String::from_utf8_lossy(&bytes), Path::new("c.json"));
    }
}
