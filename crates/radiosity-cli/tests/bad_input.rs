//! The program on bad input: exit code 1 (an error, not a panic's 101) and a message on
//! stderr that names the file and line. Each run reads a tiny scene or fails while
//! loading, so the whole file runs in a few seconds.

use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-bad-input");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn write(name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = tmp(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Runs `radiosity <args>`; returns (exit code, stderr).
fn run(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `radiosity solve <file> --report r.json -q --mesh-size 1000`.
fn solve(file: &Path) -> (Option<i32>, String) {
    let report = tmp("r.json");
    run(&["solve", file.to_str().unwrap(), "--report", report.to_str().unwrap(), "-q", "--mesh-size", "1000"])
}

/// Asserts a solve of `file` fails with exit code 1 and stderr naming `named` (e.g.
/// "file.obj:3:").
fn fails(file: &Path, named: &str) {
    let (code, err) = solve(file);
    assert_eq!(code, Some(1), "{}: exit code {code:?}, stderr: {err}", file.display());
    assert!(err.contains(named), "{}: stderr should name {named}: {err}", file.display());
    assert!(!err.contains("panicked"), "{err}");
}

fn at(name: &str, line: usize) -> String {
    format!("{}:{line}:", tmp(name).display())
}

const MTL: &str = "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n";

#[test]
fn obj_and_mtl_errors() {
    write("good.mtl", MTL);
    fails(&write("nan.obj", "mtllib good.mtl\nv 0 0 0\nv 1 nan 0\n"), &at("nan.obj", 3));
    fails(&write("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"), &at("range.obj", 4));
    fails(&write("nomtl.obj", "mtllib missing.mtl\nv 0 0 0\n"), &at("nomtl.obj", 1));
    write("black.mtl", "newmtl black\nKd -1 1 1\n");
    fails(&write("black.obj", "mtllib black.mtl\nv 0 0 0\n"), &at("black.mtl", 2));
    write("neg.mtl", "newmtl a\nKd 0.5 0.5 0.5\nKe -1 0 0\n");
    fails(&write("neg.obj", "mtllib neg.mtl\n"), &at("neg.mtl", 3));
    fails(&write("empty.obj", ""), "empty.obj");
    let garbage: Vec<u8> = (0..2000u32).map(|i| (i.wrapping_mul(2654435761) >> 11) as u8).collect();
    fails(&write("garbage.obj", garbage), "garbage.obj");
    fails(&tmp("does-not-exist.obj"), "does-not-exist.obj");
}

#[test]
fn degenerate_polygons_warn_and_the_solve_succeeds() {
    write("good.mtl", MTL);
    let f = write(
        "degenerate.obj",
        "mtllib good.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nusemtl lamp\nf 1 2 3\nf 1 2 4\n",
    );
    let (code, err) = solve(&f);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains(&format!("warning: {}", at("degenerate.obj", 8))), "{err}");
}

fn gltf_text(base_color: &str, positions: [[f32; 3]; 3]) -> String {
    use std::fmt::Write as _;
    let bytes: Vec<u8> = positions.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
    // Minimal base64 (standard alphabet, padded) so this crate needs no extra dependency.
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut b64 = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16) | (u32::from(*c.get(1).unwrap_or(&0)) << 8) | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                b64.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                b64.push('=');
            }
        }
    }
    let mut s = String::new();
    write!(
        s,
        r#"{{
  "asset": {{"version": "2.0"}},
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0, "name": "tri"}}],
  "meshes": [{{"name": "m", "primitives": [{{"attributes": {{"POSITION": 0}}, "material": 0}}]}}],
  "materials": [
    {{
      "name": "paint",
      "emissiveFactor": [1, 1, 1],
      "pbrMetallicRoughness": {{"baseColorFactor": {base_color}}}
    }}
  ],
  "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}}],
  "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
  "buffers": [{{"byteLength": 36, "uri": "data:application/octet-stream;base64,{b64}"}}]
}}
"#
    )
    .unwrap();
    s
}

const TRI: [[f32; 3]; 3] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]];

#[test]
fn gltf_errors() {
    // The good file solves.
    let (code, err) = solve(&write("good.gltf", gltf_text("[0.5, 0.5, 0.5, 1]", TRI)));
    assert_eq!(code, Some(0), "{err}");
    // baseColorFactor 1 (glTF's default white): lowered with a warning; refused with --strict.
    let white = write("white.gltf", gltf_text("[1, 1, 1, 1]", TRI));
    let (code, err) = solve(&white);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning:") && err.contains("lowered to 0.95") && err.contains(&format!("'paint' ({}", at("white.gltf", 7).trim_end_matches(':'))), "{err}");
    let (code, err) = run(&["solve", white.to_str().unwrap(), "--strict", "-q", "--mesh-size", "1000"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&at("white.gltf", 7)) && err.contains("'paint'"), "{err}");
    fails(&write("nan.gltf", gltf_text("[0.5, 0.5, 0.5, 1]", [[0., 0., 0.], [f32::NAN, 0., 0.], [0., 1., 0.]])), "nan.gltf:");
    fails(&write("syntax.gltf", "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [}\n"), &at("syntax.gltf", 3));
    fails(&write("truncated.glb", b"glTF\x02\x00\x00\x00\xff\x00\x00\x00JSON"), "truncated.glb");
    fails(&write("garbage.glb", [0u8, 159, 146, 150, 255, 1, 2]), "garbage.glb");
    let text = gltf_text("[0.5, 0.5, 0.5, 1]", TRI).replace("\"data:application/octet-stream;base64,", "\"nowhere.bin\", \"x\": \"");
    fails(&write("missing-bin.gltf", text), "nowhere.bin");
}

#[test]
fn toml_errors() {
    fails(&write("unknown.toml", "mesh = \"builtin:furnace\"\n[materials.furnace]\nemision = [1, 1, 1]\n"), &format!("{}:3:1:", tmp("unknown.toml").display()));
    fails(&write("nomesh.toml", "# a comment\nmesh = \"nowhere.obj\"\n"), &at("nomesh.toml", 2));
    fails(&write("nan.toml", "mesh = \"builtin:furnace\"\n[materials.furnace]\nemission = [nan, 1, 1]\n"), &at("nan.toml", 3));
    fails(&write("type.toml", "mesh = [1, 2]\n"), &at("type.toml", 1));
    fails(&write("nomat.toml", "mesh = \"builtin:furnace\"\n[materials.lamp]\nemission = [1, 1, 1]\n"), &at("nomat.toml", 2));
    // The mesh's own error names the mesh file and line.
    write("bad-mesh.obj", "v 0 0 0\nv 0 0 inf\n");
    fails(&write("badmesh.toml", "mesh = \"bad-mesh.obj\"\n"), &at("bad-mesh.obj", 2));
}

#[test]
fn camera_json_errors() {
    let cam = write("cam.json", "{\n  \"position\": [0.5, 0.5, 0.1],\n  \"look_at\": [0.5, 0.5, 0.1],\n  \"up\": [0, 1, 0],\n  \"vfov_deg\": 60\n}\n");
    let png = tmp("cam.png");
    let (code, err) = run(&[
        "render", "furnace", "--camera", cam.to_str().unwrap(), "-o", png.to_str().unwrap(), "-q",
        "--mesh-size", "1", "--width", "8", "--height", "8",
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&at("cam.json", 3)), "{err}");
    let cam = write("cam-syntax.json", "{\n  \"position\": [0.5, 0.5,\n");
    let (code, err) = run(&[
        "render", "furnace", "--camera", cam.to_str().unwrap(), "-o", png.to_str().unwrap(), "-q",
        "--mesh-size", "1", "--width", "8", "--height", "8",
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&at("cam-syntax.json", 3)), "{err}");
}

// ---------------------------------------------------------------- hostile-input audit

#[test]
fn scene_that_is_dev_zero_a_fifo_or_a_directory_is_refused() {
    let zero = tmp("zero.obj");
    let _ = std::fs::remove_file(&zero);
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let t = std::time::Instant::now();
    fails(&zero, &format!("{}: is not a regular file", zero.display()));
    let fifo = tmp("fifo.obj");
    let _ = std::fs::remove_file(&fifo);
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    fails(&fifo, &format!("{}: is not a regular file", fifo.display()));
    let dir = tmp("dir.obj");
    std::fs::create_dir_all(&dir).unwrap();
    fails(&dir, &format!("{}: is a directory", dir.display()));
    write("good.mtl", MTL);
    let mesh_dir = write("dir-mesh.toml", "mesh = \"dir.obj\"\n");
    let (code, err) = solve(&mesh_dir);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&at("dir-mesh.toml", 1)) && err.contains(&format!("mesh file '{}' is a directory", dir.display())), "{err}");
    // A camera that is /dev/zero.
    let cam = tmp("zero.json");
    let _ = std::fs::remove_file(&cam);
    std::os::unix::fs::symlink("/dev/zero", &cam).unwrap();
    let png = tmp("z.png");
    let (code, err) = run(&["render", "furnace", "--camera", cam.to_str().unwrap(), "-o", png.to_str().unwrap(), "-q", "--mesh-size", "1"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains(&format!("{}: is not a regular file", cam.display())), "{err}");
    assert!(t.elapsed().as_secs() < 30, "{:?}", t.elapsed());
}

#[test]
fn polygon_with_500000_vertices_is_refused_in_seconds() {
    use std::fmt::Write as _;
    write("good.mtl", MTL);
    let n = 500_000;
    let mut s = String::from("mtllib good.mtl\nusemtl lamp\n");
    for i in 0..n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        writeln!(s, "v {} {} 0", a.cos(), a.sin()).unwrap();
    }
    s.push('f');
    for i in 1..=n {
        write!(s, " {i}").unwrap();
    }
    s.push('\n');
    let f = write("ngon500k.obj", s);
    let t = std::time::Instant::now();
    fails(&f, &format!("{} polygon has 500000 vertices; at most 10000", at("ngon500k.obj", n + 3)));
    assert!(t.elapsed().as_secs() < 20, "{:?}", t.elapsed());
}

#[test]
fn strict_flag_refuses_reflectance_of_one_on_render_solve_and_viewfactors() {
    write("white.mtl", "newmtl white\nKd 1 1 1\nnewmtl lamp\nKd 0 0 0\nKe 1 1 1\n");
    let obj = write(
        "white.obj",
        "mtllib white.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nusemtl white\nf 1 2 3 4\nusemtl lamp\nf 1 4 5\n",
    );
    let (code, err) = solve(&obj);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains(&format!("'white' ({})", at("white.mtl", 2).trim_end_matches(':'))) && err.contains("lowered to 0.95"), "{err}");
    let o = obj.to_str().unwrap();
    let png = tmp("white.png");
    let csv = tmp("white.csv");
    for args in [
        vec!["solve", o, "--strict", "-q", "--mesh-size", "1000"],
        vec!["render", o, "--strict", "-q", "--mesh-size", "1000", "-o", png.to_str().unwrap(), "--width", "8", "--height", "8"],
        vec!["viewfactors", o, "--strict", "-q", "-o", csv.to_str().unwrap()],
    ] {
        let (code, err) = run(&args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(err.contains(&at("white.mtl", 2)) && err.contains("[0, 1)"), "{args:?}: {err}");
    }
}

#[test]
fn scene_without_light_fails_render_and_solve_but_not_viewfactors() {
    write("good.mtl", MTL);
    // The only emitter is degenerate (line 9).
    let f = write("dark.obj", "mtllib good.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl grey\nf 1 2 3 4\nusemtl lamp\nf 1 2 2\n");
    let (code, err) = solve(&f);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(&format!("{}: no surface emits light: 1 emitting polygon was skipped (first at {}9: degenerate)", tmp("dark.obj").display(), at("dark.obj", 9).trim_end_matches("9:"))),
        "{err}"
    );
    let png = tmp("dark.png");
    let (code, err) = run(&["render", f.to_str().unwrap(), "-q", "--mesh-size", "1000", "-o", png.to_str().unwrap(), "--width", "8", "--height", "8"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("no surface emits light") && !png.exists(), "{err}");
    // View factors need no light.
    let csv = tmp("dark.csv");
    let (code, err) = run(&["viewfactors", f.to_str().unwrap(), "-q", "-o", csv.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(csv.exists());
}

#[test]
fn camera_flags_at_extreme_or_degenerate_values_are_refused() {
    let png = tmp("cam-flags.png");
    for (flag, value, why) in [
        ("--eye", "1e308,0.5,0.5", "above 1e30"),
        ("--look-at", "0.5,0.5,0.5", "coincide"),
        ("--up", "0,0,1", "parallel"),
        ("--fov", "180", "between 0 and 180"),
    ] {
        let mut args = vec!["render", "furnace", "-o", png.to_str().unwrap(), "-q", "--mesh-size", "1", "--width", "8", "--height", "8"];
        if flag != "--eye" && flag != "--look-at" {
            args.extend(["--eye", "0.5,0.5,-2", "--look-at", "0.5,0.5,0.5"]);
        } else if flag == "--look-at" {
            args.extend(["--eye", "0.5,0.5,0.5"]);
        }
        args.extend([flag, value]);
        let (code, err) = run(&args);
        assert_eq!(code, Some(1), "{flag} {value}: {err}");
        assert!(err.contains("--eye/--look-at/--up/--fov") && err.contains(why), "{flag} {value}: {err}");
    }
    // NaN is refused by the flag's own parser (a usage error).
    let (code, err) = run(&["render", "furnace", "-o", png.to_str().unwrap(), "-q", "--eye", "nan,0.5,0.5"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("finite"), "{err}");
}
