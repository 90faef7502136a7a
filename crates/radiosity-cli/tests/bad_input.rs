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
    // Written beside and renamed into place: tests run in parallel and several write the same
    // shared file (`good.mtl`), which a plain rewrite leaves empty for a moment under another
    // test's reader.
    let p = tmp(name);
    let part = tmp(&format!("{name}.{:?}.part", std::thread::current().id()));
    std::fs::write(&part, bytes).unwrap();
    std::fs::rename(&part, &p).unwrap();
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

// ---- The hostile-input audit: each case is refused before any work, with a message that
// names the option or file and the reason, or gives a correct result.

/// Runs `radiosity <args>` in `dir`; returns (exit code, stderr, seconds).
fn run_in(dir: &Path, args: &[&str]) -> (Option<i32>, String, f64) {
    let t = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_radiosity")).args(args).current_dir(dir).output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned(), t.elapsed().as_secs_f64())
}

fn case_dir(name: &str) -> PathBuf {
    let d = tmp(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The refusal of a run: exit code 1, no panic, stderr naming every one of `named`, and no
/// sign that the work started (no solver iteration, no element count).
fn refused(code: Option<i32>, err: &str, named: &[&str]) {
    assert_eq!(code, Some(1), "exit code {code:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in named {
        assert!(err.contains(n), "stderr should name {n}: {err}");
    }
    assert!(!err.contains(" iteration ") && !err.contains(" elements, "), "the work started: {err}");
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn time_budget_1e300_is_refused_not_a_panic() {
    let d = case_dir("time-budget");
    for t in ["1e300", "inf", "0", "-5"] {
        let t = &format!("--time-budget={t}");
        let (code, err, _) = run_in(&d, &["solve", "furnace", "--mesh-size", "1", t, "--report", "r.json"]);
        refused(code, &err, &["--time-budget"]);
    }
    let (_, err, _) = run_in(&d, &["solve", "furnace", "--mesh-size", "1", "--time-budget", "1e300"]);
    assert!(err.contains("at most 1e9 seconds"), "{err}");
    assert!(files_in(&d).is_empty(), "{:?}", files_in(&d));
    // A large but sane budget works.
    let (code, err, _) = run_in(&d, &["solve", "furnace", "--mesh-size", "1", "--time-budget", "1e9", "-q", "--report", "r.json"]);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn image_sizes_zero_absurd_or_beyond_memory_are_refused() {
    let d = case_dir("image-size");
    for (flag, v) in [("--width", "0"), ("--height", "0"), ("--width", "65536"), ("--height", "100000"), ("--width", "12.5")] {
        let (code, err, _) = run_in(&d, &["render", "furnace", flag, v, "-o", "x.png"]);
        assert_eq!(code, Some(2), "{flag} {v}: {err}");
        assert!(err.contains(flag) && (err.contains("between 1 and 65535") || err.contains("whole number")), "{err}");
    }
    // 65535² passes parsing but its buffers (hundreds of GiB) exceed any memory available.
    let (code, err, secs) =
        run_in(&d, &["render", "furnace", "--width", "65535", "--height", "65535", "--render", "gouraud", "-o", "x.png"]);
    refused(code, &err, &["65535×65535", "memory", "--width/--height"]);
    assert!(secs < 10.0, "{secs} s before the refusal");
    assert!(files_in(&d).is_empty(), "{:?}", files_in(&d));
}

#[test]
fn duplicate_view_names_are_refused_naming_the_file_and_the_name() {
    let d = case_dir("dup-views");
    let cam = r#""position": [0.5, 0.5, 0.05], "look_at": [0.5, 0.5, 1], "up": [0, 1, 0], "vfov_deg": 60"#;
    std::fs::write(d.join("views.json"), format!("[{{\"name\": \"a\", {cam}}}, {{\"name\": \"b\", {cam}}}, {{\"name\": \"a\", {cam}}}]")).unwrap();
    let (code, err, _) = run_in(&d, &["render", "furnace", "--views", "views.json", "-o", "out.png", "--width", "8", "--height", "8"]);
    refused(code, &err, &["views.json", "'a'", "views 0 and 2", "distinct"]);
    assert_eq!(files_in(&d), ["views.json"]);
}

#[test]
fn outputs_that_are_one_file_are_refused_before_any_work() {
    let d = case_dir("same-output");
    let base = ["render", "furnace", "--mesh-size", "0.5", "--width", "8", "--height", "8"];
    std::fs::create_dir_all(d.join("sub")).unwrap();
    for (extra, named) in [
        (&["-o", "x.png", "--exr", "x.png"][..], &["-o x.png", "--exr x.png"][..]),
        (&["-o", "x.png", "--report", "x.png"], &["-o x.png", "--report x.png"]),
        (&["-o", "x.png", "--report", "./sub/../x.png"], &["-o x.png", "--report ./sub/../x.png"]),
        (&["-o", "x.png", "--frames", ".", "--report", "frames.json"], &["--frames", "--report frames.json"]),
    ] {
        let (code, err, _) = run_in(&d, &[&base[..], extra].concat());
        refused(code, &err, &[named, &["outputs must be distinct"]].concat());
        assert_eq!(files_in(&d), ["sub"], "{extra:?}");
    }
    let (code, err, _) = run_in(&d, &["solve", "furnace", "--report", "p.png", "--plot", "p.png"]);
    refused(code, &err, &["--report p.png", "--plot p.png", "distinct"]);
    // A view's image (out_b.png for view "b") and the report.
    let cam = r#""position": [0.5, 0.5, 0.05], "look_at": [0.5, 0.5, 1], "up": [0, 1, 0], "vfov_deg": 60"#;
    let views = d.join("sub/views.json");
    std::fs::write(&views, format!("[{{\"name\": \"a\", {cam}}}, {{\"name\": \"b\", {cam}}}]")).unwrap();
    let (code, err, _) = run_in(&d, &[&base[..], &["--views", "sub/views.json", "-o", "out.png", "--report", "out_b.png"]].concat());
    refused(code, &err, &["-o out_b.png", "--report out_b.png", "distinct"]);
    assert_eq!(files_in(&d), ["sub"]);
}

#[cfg(unix)]
#[test]
fn special_files_and_directories_are_never_replaced() {
    use std::os::unix::fs::FileTypeExt;
    let d = case_dir("special");
    assert!(Command::new("mkfifo").arg(d.join("fifo")).status().unwrap().success());
    std::fs::create_dir_all(d.join("folder")).unwrap();
    for (flag, target, why) in [
        ("-o", "fifo", "FIFO"),
        ("--report", "fifo", "FIFO"),
        ("--exr", "fifo", "FIFO"),
        ("-o", "folder", "is a directory"),
        ("--report", "folder", "is a directory"),
    ] {
        let mut args = vec!["render", "furnace", "--mesh-size", "0.5", "--width", "8", "--height", "8"];
        if flag != "-o" {
            args.extend(["-o", "ok.png"]);
        }
        args.extend([flag, target]);
        let (code, err, _) = run_in(&d, &args);
        refused(code, &err, &[flag, target, why]);
        assert!(std::fs::metadata(d.join("fifo")).unwrap().file_type().is_fifo());
        assert!(d.join("folder").is_dir());
        assert_eq!(files_in(&d), ["fifo", "folder"]);
    }
    // A folder that cannot be created (a file is in the way).
    std::fs::write(d.join("plain"), b"").unwrap();
    let (code, err, _) = run_in(&d, &["solve", "furnace", "--report", "plain/r.json"]);
    refused(code, &err, &["--report", "plain", "not a folder"]);
    // viewfactors checks its outputs too.
    let (code, err, _) = run_in(&d, &["viewfactors", "furnace", "-o", "fifo", "--format", "csv"]);
    refused(code, &err, &["-o", "fifo", "FIFO"]);
}

#[cfg(target_os = "linux")]
#[test]
fn outputs_in_a_read_only_folder_are_refused_before_the_solve() {
    use std::os::unix::fs::PermissionsExt;
    let d = case_dir("read-only");
    let ro = d.join("ro");
    std::fs::create_dir_all(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    // Root writes into a mode-555 folder anyway; /proc refuses everyone.
    let target = if running_as_root() { PathBuf::from("/proc/radiosity-report.json") } else { ro.join("r.json") };
    let (code, err, _) = run_in(&d, &["solve", "cornell", "--report", target.to_str().unwrap()]);
    refused(code, &err, &["--report", "cannot write in folder"]);
    assert!(!target.exists());
    assert!(std::fs::read_dir(&ro).unwrap().next().is_none(), "files left in the read-only folder");
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// True when the tests run as root (uid 0), read from /proc.
#[cfg(target_os = "linux")]
fn running_as_root() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("Uid:")).map(|l| l.split_whitespace().nth(1) == Some("0")))
        .unwrap_or(false)
}

#[test]
fn direct_solver_too_large_is_refused_right_after_meshing() {
    let d = case_dir("direct");
    // ~23 000 elements: a dense matrix of 4 GiB, over the 2 GiB limit; the form factors alone
    // would take minutes.
    let (code, err, secs) = run_in(&d, &["solve", "cornell", "--solver", "direct", "--mesh-size", "10", "--report", "r.json"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("the direct solve of") && err.contains("limit 2.0 GiB") && err.contains("--solver gauss-seidel"), "{err}");
    assert!(secs < 20.0, "refused after {secs} s");
    assert!(files_in(&d).is_empty());
}

#[test]
fn element_cap_advice_never_repeats_the_size_in_use() {
    let d = case_dir("cap");
    // Fewer elements allowed than the scene has polygons: no mesh size can help.
    let (code, err, _) = run_in(&d, &["solve", "furnace", "--mesh-size", "1.4142", "--max-elements", "5"]);
    refused(code, &err, &["6 polygons", "raise --max-elements to at least 6"]);
    assert!(!err.contains("or larger"), "{err}");
    // Otherwise the advice is a larger size that meets the cap.
    let (code, err, _) = run_in(&d, &["solve", "furnace", "--mesh-size", "0.01", "--max-elements", "600"]);
    refused(code, &err, &["limit 600", "use --mesh-size"]);
    let size = err.split("use --mesh-size ").nth(1).unwrap().split(' ').next().unwrap();
    assert!(size.parse::<f64>().unwrap() > 0.01, "{err}");
    let (code, err, _) = run_in(&d, &["solve", "furnace", "--mesh-size", size, "--max-elements", "600", "-q", "--report", "r.json"]);
    assert_eq!(code, Some(0), "the advised --mesh-size {size} is refused: {err}");
}

#[test]
fn thread_counts_out_of_range_are_refused_at_once() {
    let d = case_dir("threads");
    for args in [
        &["solve", "cornell", "--threads", "5000"][..],
        &["render", "cornell", "--threads", "5000", "-o", "x.png"],
        &["solve", "cornell", "--threads", "0"],
        &["viewfactors", "cornell", "-o", "f.csv", "--threads", "5000"],
    ] {
        let (code, err, secs) = run_in(&d, args);
        refused(code, &err, &["--threads", "between 1 and 1024"]);
        assert!(secs < 5.0, "{args:?}: {secs} s");
    }
    assert!(files_in(&d).is_empty());
}

/// An OBJ cube of side 1 whose faces look inwards (a closed room), without a camera:
/// `NAME.obj` with `NAME.mtl` holding `mtl`, the walls of material `wall`, then `extra`.
fn cube_room(d: &Path, name: &str, mtl: &str, extra: &str) -> PathBuf {
    std::fs::write(d.join(format!("{name}.mtl")), mtl).unwrap();
    let mut obj = format!("mtllib {name}.mtl\nusemtl wall\n");
    for (x, y, z) in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)] {
        obj.push_str(&format!("v {x} {y} {z}\n"));
    }
    // Counter-clockwise seen from inside.
    for f in ["1 2 3 4", "5 8 7 6", "1 5 6 2", "4 3 7 8", "1 4 8 5", "2 6 7 3"] {
        obj.push_str(&format!("f {f}\n"));
    }
    obj.push_str(extra);
    let p = d.join(format!("{name}.obj"));
    std::fs::write(&p, obj).unwrap();
    p
}

/// The closed room with glowing grey walls.
fn closed_room(d: &Path) -> PathBuf {
    cube_room(d, "room", "newmtl wall\nKd 0.5 0.5 0.5\nKe 1 1 1\n", "")
}

#[test]
fn camera_that_sees_only_back_faces_or_nothing_warns() {
    let d = case_dir("black");
    let base = ["render", "furnace", "--mesh-size", "0.5", "--width", "16", "--height", "16", "--render", "gouraud", "-o", "x.png"];
    // Outside the closed furnace, looking at it.
    let (code, err, _) = run_in(&d, &[&base[..], &["--eye", "0.5,0.5,-2", "--look-at", "0.5,0.5,0.5"]].concat());
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning: view 'main': the camera at (0.5, 0.5, -2) sees only back faces"), "{err}");
    assert!(err.contains("use --two-sided or move the camera inside"), "{err}");
    // Two-sided walls are seen from outside: no warning about the view (their outer sides
    // glow too, and the hint about two-sided emitters says so).
    let (_, err, _) = run_in(&d, &[&base[..], &["--eye", "0.5,0.5,-2", "--look-at", "0.5,0.5,0.5", "--two-sided"]].concat());
    assert!(!err.contains("warning: view"), "{err}");
    assert!(err.contains("is emitted by the back sides of two-sided emitters ('furnace')"), "{err}");
    // Looking away from everything.
    let (_, err, _) = run_in(&d, &[&base[..], &["--eye", "0.5,0.5,-2", "--look-at", "0.5,0.5,-3"]].concat());
    assert!(err.contains("sees no surface"), "{err}");
    // The furnace's own camera is inside: no warning.
    let (_, err, _) = run_in(&d, &base);
    assert!(!err.contains("warning"), "{err}");
}

#[test]
fn default_camera_of_a_closed_room_is_placed_inside() {
    let d = case_dir("room");
    let room = closed_room(&d);
    let (code, err, _) = run_in(&d, &["render", room.to_str().unwrap(), "--mesh-size", "0.5", "--width", "16", "--height", "16", "--render", "gouraud", "-o", "x.png", "--exr", "x.exr"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("using a camera inside"), "{err}");
    assert!(!err.contains("warning"), "{err}");
    let img = radiosity::output::exr::read(&d.join("x.exr")).unwrap();
    let lit = img.pixels.iter().filter(|p| p.x > 0.0).count();
    assert_eq!(lit, 16 * 16, "the room fills the image from inside");
}

/// A closed unit room of grey walls (inward) lit by a lamp under its ceiling, facing down.
fn lamp_room(d: &Path) -> PathBuf {
    cube_room(
        d,
        "lamp-room",
        "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n",
        "v 0.4 0.95 0.4\nv 0.6 0.95 0.4\nv 0.6 0.95 0.6\nv 0.4 0.95 0.6\nusemtl lamp\nf 9 10 11 12\n",
    )
}

#[test]
fn default_camera_outside_a_two_sided_room_moves_inside_and_an_explicit_one_is_warned() {
    let d = case_dir("lamp-room");
    let room = lamp_room(&d);
    let base = ["render", room.to_str().unwrap(), "--two-sided", "--mesh-size", "0.25", "--width", "16", "--height", "16", "--render", "gouraud", "-o", "x.png", "--exr", "x.exr"];
    let (code, err, _) = run_in(&d, &base);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("sees lit surfaces in 0.0 % of the image; using a camera inside"), "{err}");
    assert!(!err.contains("warning: view"), "{err}");
    let img = radiosity::output::exr::read(&d.join("x.exr")).unwrap();
    let lit = img.pixels.iter().filter(|p| p.x > 0.0).count();
    assert_eq!(lit, 16 * 16, "the room fills the image from inside");
    let (code, err, _) = run_in(&d, &[&base[..], &["--eye", "0.5,0.5,-2", "--look-at", "0.5,0.5,0.5"]].concat());
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning: view 'main': the camera at (0.5, 0.5, -2) sees lit surfaces in only 0.0 % of the image"), "{err}");
    assert!(!err.contains("using a camera inside"), "{err}");
}

/// `--max-iterations 0` leaves B = E (only the lamp lit), but the final gather still shows the
/// lamp's direct light: the camera check judges lit surfaces by one bounce then, and neither
/// warns of a black image nor moves the camera (2026-12-06 sweep: "sees lit surfaces in
/// only 0.5 %" over an image 70 % lit).
#[test]
fn no_black_image_warning_when_solving_stops_before_the_first_bounce() {
    let d = case_dir("max-iterations-0");
    let (code, err, _) = run_in(&d, &["render", "cornell", "--max-iterations", "0", "--width", "16", "--height", "16", "--spp", "1", "-o", "x.png", "--exr", "x.exr"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("sees lit surfaces"), "{err}");
    let img = radiosity::output::exr::read(&d.join("x.exr")).unwrap();
    let lit = img.pixels.iter().filter(|p| p.x > 0.0).count();
    assert!(lit * 2 > img.pixels.len(), "{lit} of {} pixels lit", img.pixels.len());
}

/// A box open towards +z (as the McGuire and glTF Cornell boxes are, where Cornell's own data
/// opens towards −z), one-sided walls facing in, a lamp under its ceiling.
fn box_open_towards_plus_z(d: &Path, name: &str, two_sided_toml: bool) -> PathBuf {
    std::fs::write(d.join("open.mtl"), "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n").unwrap();
    let mut obj = String::from("mtllib open.mtl\nusemtl wall\n");
    for (x, y, z) in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)] {
        obj.push_str(&format!("v {x} {y} {z}\n"));
    }
    // cube_room's faces without the one at z = 1.
    for f in ["1 2 3 4", "1 5 6 2", "4 3 7 8", "1 4 8 5", "2 6 7 3"] {
        obj.push_str(&format!("f {f}\n"));
    }
    obj.push_str("v 0.4 0.95 0.4\nv 0.6 0.95 0.4\nv 0.6 0.95 0.6\nv 0.4 0.95 0.6\nusemtl lamp\nf 9 10 11 12\n");
    std::fs::write(d.join("open.obj"), obj).unwrap();
    if two_sided_toml {
        // Two-sided walls: the outside of the back wall is seen, dark, before the solve
        // shows it unlit.
        let p = d.join(format!("{name}.toml"));
        std::fs::write(&p, "mesh = \"open.obj\"\ntwo_sided = true\n[materials.lamp]\ntwo_sided = false\n").unwrap();
        p
    } else {
        d.join("open.obj")
    }
}

#[test]
fn default_camera_behind_a_box_open_on_the_far_side_looks_from_the_open_side() {
    let d = case_dir("open-box");
    for two_sided in [false, true] {
        let scene = box_open_towards_plus_z(&d, "open", two_sided);
        let args = ["render", scene.to_str().unwrap(), "--mesh-size", "0.25", "--width", "16", "--height", "16", "--render", "gouraud", "-o", "x.png", "--exr", "x.exr"];
        let (code, err, _) = run_in(&d, &args);
        assert_eq!(code, Some(0), "{err}");
        assert!(err.contains("using the same view from the opposite side at (0.5000, "), "two-sided {two_sided}: {err}");
        assert!(!err.contains("warning: view"), "{err}");
        // From the open side the lit inside fills most of the frame.
        let img = radiosity::output::exr::read(&d.join("x.exr")).unwrap();
        let lit = img.pixels.iter().filter(|p| p.x > 0.0).count();
        assert!(lit * 2 > 16 * 16, "two-sided {two_sided}: {lit} of 256 pixels lit");
    }
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

/// A glowing unit floor (one-sided, facing up) under a wide two-sided blocker with a wide
/// two-sided ceiling above it (`b.toml`). Analytic factors see the ceiling through the
/// blocker, so the floor's light is received twice: the books close only with a negative
/// escaped term (−14.6 % here). Before light told the sides of two-sided polygons apart
/// (`mesh::lit_sides`), the floor, seeing only the blocker's back copy, read as inside a
/// solid: this scene was refused, and with the floor two-sided its upper side was lost.
fn floor_blocker_ceiling(d: &Path) -> PathBuf {
    std::fs::write(d.join("b.mtl"), "newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\nnewmtl grey\nKd 0.8 0.8 0.8\n").unwrap();
    let obj = "mtllib b.mtl\n\
        v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
        v -4.5 -4.5 1\nv 5.5 -4.5 1\nv 5.5 5.5 1\nv -4.5 5.5 1\n\
        v -4.5 -4.5 0.5\nv 5.5 -4.5 0.5\nv 5.5 5.5 0.5\nv -4.5 5.5 0.5\n\
        usemtl lamp\nf 1 2 3 4\nusemtl grey\nf 5 8 7 6\nf 9 10 11 12\n";
    std::fs::write(d.join("b.obj"), obj).unwrap();
    let p = d.join("b.toml");
    std::fs::write(&p, "mesh = \"b.obj\"\ntwo_sided = true\n[materials.lamp]\ntwo_sided = false\n").unwrap();
    p
}

#[test]
fn created_light_is_warned_even_under_quiet() {
    let d = case_dir("created");
    floor_blocker_ceiling(&d);
    let base = ["solve", "b.toml", "--mesh-size", "0.5", "-q", "--report", "r.json"];
    let (code, err, _) = run_in(&d, &[&base[..], &["--form-factors", "analytic"]].concat());
    assert_eq!(code, Some(0), "{err}");
    // The energy line's own escaped term is below −1 % of the emitted power.
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("r.json")).unwrap()).unwrap();
    let e = &report["energy"];
    let escaped = e["escaped"][1].as_f64().unwrap() / e["emitted"][1].as_f64().unwrap();
    assert!(escaped < -0.01, "escaped {escaped}");
    assert!(err.contains("warning: the solution created light"), "{err}");
    assert!(err.contains("analytic form factors ignore occlusion, so surfaces exchange light"), "{err}");
    // Under -q, the form-factor warnings print as well.
    assert!(err.contains("warning: form factors:"), "{err}");
    let warnings = report["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().starts_with("the solution created light")), "{warnings:?}");
    // Occluded factors deliver what was sent: no such warning.
    let (code, err, _) = run_in(&d, &[&base[..], &["--form-factors", "point-sampled"]].concat());
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("created light"), "{err}");
}

#[test]
fn two_sided_lamp_in_a_ceiling_is_hinted_and_the_toml_override_closes_the_room() {
    let d = case_dir("two_sided_lamp");
    // A closed cube room whose whole ceiling (z = 1) is the lamp; its back side faces out.
    let mtl = "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n";
    std::fs::write(d.join("room.mtl"), mtl).unwrap();
    let mut obj = String::from("mtllib room.mtl\n");
    for (x, y, z) in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)] {
        obj.push_str(&format!("v {x} {y} {z}\n"));
    }
    obj.push_str("usemtl wall\nf 1 2 3 4\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\nf 2 6 7 3\nusemtl lamp\nf 5 8 7 6\n");
    std::fs::write(d.join("room.obj"), obj).unwrap();
    std::fs::write(d.join("room.toml"), "mesh = \"room.obj\"\ntwo_sided = true\n[materials.lamp]\ntwo_sided = false\n").unwrap();
    let escaped = |d: &Path| {
        let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("r.json")).unwrap()).unwrap();
        r["energy"]["escaped"][1].as_f64().unwrap() / r["energy"]["emitted"][1].as_f64().unwrap()
    };
    let base = ["solve", "--mesh-size", "0.25", "-q", "--report", "r.json"];
    let (code, err, _) = run_in(&d, &[&base[..], &["room.obj", "--two-sided"]].concat());
    assert_eq!(code, Some(0), "{err}");
    // Half the lamp's light leaves through its back: 50 % escapes, exactly by geometry.
    assert!((escaped(&d) - 0.5).abs() < 1e-3, "escaped {}", escaped(&d));
    assert!(err.contains("warning: 50.0 % of the emitted light escapes, and 50.0 % is emitted by the back sides of two-sided emitters ('lamp')"), "{err}");
    assert!(err.contains("[materials.NAME] two_sided = false"), "{err}");
    // The lamp kept one-sided: the room is closed, nothing escapes, no hint.
    let (code, err, _) = run_in(&d, &[&base[..], &["room.toml"]].concat());
    assert_eq!(code, Some(0), "{err}");
    assert!(escaped(&d).abs() < 1e-3, "escaped {}", escaped(&d));
    assert!(!err.contains("warning"), "{err}");
}

/// An output named for another format is refused before any work, not written in ours
/// (2026-12-06 sweep: `-o a.jpg` wrote PNG data, `--exr a.txt` EXR data).
#[test]
fn output_named_for_another_format_is_refused() {
    let d = case_dir("output-format");
    for (args, named) in [
        (&["render", "cornell", "-o", "a.jpg"][..], &["-o a.jpg", "PNG", ".png"][..]),
        (&["render", "cornell", "-o", "a.png", "--exr", "a.txt"], &["--exr a.txt", "OpenEXR", ".exr"]),
        (&["solve", "cornell", "--plot", "p.jpg"], &["--plot p.jpg", "PNG"]),
    ] {
        let (code, err, _) = run_in(&d, args);
        refused(code, &err, named);
        assert!(files_in(&d).is_empty(), "{:?}", files_in(&d));
    }
    // Any case of the right extension is taken.
    let (code, err, _) = run_in(&d, &["render", "cornell", "--width", "8", "--height", "8", "--spp", "1", "-o", "A.PNG", "-q"]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(files_in(&d), ["A.PNG"]);
}

/// Flags of a part that the run does not use are not silently ignored (2026-12-06 sweep):
/// link settings with `--transport rows` and final-gather settings with `--render flat` are
/// refused; link settings when auto picks rows are warned about; `--sun-diameter` needs
/// `--sun`.
#[test]
fn flags_for_a_part_the_run_does_not_use_are_answered() {
    let d = case_dir("unused-flags");
    let (code, err, _) = run_in(&d, &["solve", "cornell", "--transport", "rows", "--link-separation", "0.3"]);
    refused(code, &err, &["--link-separation", "--transport rows"]);
    let (code, err, _) = run_in(&d, &["render", "cornell", "--render", "flat", "--gather-rays", "3", "--shadow-rays", "3"]);
    refused(code, &err, &["--shadow-rays, --gather-rays", "--render flat"]);
    let (code, err, _) = run_in(&d, &["solve", "cornell", "--emitters-in-links", "--max-iterations", "1"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning: --emitters-in-links set the hierarchical transport's links, which this run does not use: auto picked form-factor rows"), "{err}");
    let (code, err, _) = run_in(&d, &["render", "cornell", "--sun-diameter", "2", "-o", "x.png"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--sun <X,Y,Z,E>"), "{err}");
    assert!(files_in(&d).is_empty(), "{:?}", files_in(&d));
}

/// A flag of another subcommand (`solve --frames`) is named as such, not answered by
/// clap's nearest spelling ("a similar argument exists: '--rays'").
#[test]
fn a_flag_of_another_subcommand_names_that_subcommand() {
    let d = case_dir("other-subcommand");
    let (code, err, _) = run_in(&d, &["solve", "cornell", "--frames", "f"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("`--frames` is not an option of `radiosity solve`; `radiosity render` takes it"), "{err}");
    assert!(!err.contains("--rays"), "{err}");
    let (code, err, _) = run_in(&d, &["solve", "cornell", "--exposure=2"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("`--exposure` is not an option of `radiosity solve`; `radiosity render` and `radiosity bake` take it"), "{err}");
    // A flag no subcommand takes keeps clap's answer.
    let (code, err, _) = run_in(&d, &["solve", "cornell", "--no-such-flag"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("unexpected argument '--no-such-flag'"), "{err}");
    assert!(files_in(&d).is_empty(), "{:?}", files_in(&d));
}

/// `compare --light-threshold nan` masked nothing and said so nowhere: refused.
#[test]
fn compare_light_threshold_nan_is_refused() {
    let d = case_dir("compare-nan");
    let (code, err, _) = run_in(&d, &["compare", "a.exr", "b.exr", "--light-threshold", "nan"]);
    refused(code, &err, &["--light-threshold", "positive"]);
}

/// A ViewHT temperature file that leaves surfaces of a .vs3 scene (which has no boundary
/// conditions of its own) without a temperature names the file and the surfaces, in
/// ranges, instead of listing a hundred material names.
#[test]
fn vs3_temperatures_that_leave_surfaces_unset_name_them() {
    let d = case_dir("vs3-temperatures");
    std::fs::write(d.join("t.txt"), "5 2 300\n0 0\n").unwrap();
    let vs3 = Path::new(env!("CARGO_MANIFEST_DIR")).join("../radiosity/tests/data/box345.vs3");
    let (code, err, _) = run_in(&d, &["thermal", vs3.to_str().unwrap(), "--temperatures", "t.txt"]);
    refused(code, &err, &["t.txt", "surfaces 2–5 of the 106", "surfaces 1, 6–106 need one too"]);
}
