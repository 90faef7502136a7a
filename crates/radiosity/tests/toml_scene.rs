//! TOML scene files: meshes by reference, camera, overrides, and malformed input.

use std::path::{Path, PathBuf};

use glam::DVec3;
use radiosity::pipeline::{solve_scene, Settings};
use radiosity::scene::{self, toml_file::load_toml, Scene, SceneDesc};
use radiosity::{NoProgress, Rgb};

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("toml-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn write(name: &str, text: &str) -> PathBuf {
    // Written beside and renamed into place: tests run in parallel and several write the same
    // shared file (`good.mtl`), which a plain rewrite leaves empty for a moment under another
    // test's reader.
    let p = tmp(name);
    let part = tmp(&format!("{name}.{:?}.part", std::thread::current().id()));
    std::fs::write(&part, text).unwrap();
    std::fs::rename(&part, &p).unwrap();
    p
}

fn cornell_obj() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cornell/cornell_box.obj").display().to_string()
}

fn err(name: &str, text: &str) -> String {
    let p = write(name, text);
    match load_toml(&p) {
        Ok(_) => panic!("{name} loaded but should not"),
        Err(e) => e.to_string(),
    }
}

/// Asserts the error starts with `<file>:<line>:` and returns it.
fn err_at(name: &str, text: &str, line: usize) -> String {
    let e = err(name, text);
    let want = format!("{}:{line}:", tmp(name).display());
    assert!(e.starts_with(&want), "expected {want}…, got: {e}");
    e
}

#[test]
fn obj_mesh_with_camera_and_overrides() {
    let p = write(
        "cornell.toml",
        &format!(
            "mesh = {:?}\ntwo_sided = false\n\n[camera]\nposition = [278, 273, -800]\nlook_at = [278, 273, 0]\n\
             up = [0, 1, 0]\nvfov_deg = 39.3\n\n[materials.light]\nemission = [1, 2, 3]\nreflectance = [0.1, 0.2, 0.3]\n\
             two_sided = true\n",
            cornell_obj()
        ),
    );
    let d = load_toml(&p).unwrap();
    assert_eq!(d.name, "cornell");
    let light = d.materials.iter().find(|m| m.name == "light").unwrap();
    assert_eq!(light.emission, Rgb::new(1., 2., 3.));
    assert_eq!(light.reflectance, Rgb::new(0.1, 0.2, 0.3));
    assert_eq!(light.two_sided, Some(true));
    let loc = light.loc.clone().unwrap();
    assert_eq!((loc.file.as_path(), loc.line), (p.as_path(), Some(10)));
    let c = d.camera.unwrap();
    assert_eq!(c.position, DVec3::new(278., 273., -800.));
    assert_eq!(c.vfov_deg, 39.3);
    // scene::load dispatches .toml here.
    assert_eq!(scene::load(p.to_str().unwrap()).unwrap().polygons.len(), d.polygons.len());
}

#[test]
fn camera_from_a_json_file_and_default_up() {
    std::fs::write(tmp("cam.json"), r#"{"position": [0, 1, -5], "look_at": [0, 1, 0], "up": [0, 1, 0], "vfov_deg": 50}"#)
        .unwrap();
    let d = load_toml(&write("camfile.toml", "mesh = \"builtin:furnace\"\ncamera = \"cam.json\"\n")).unwrap();
    assert_eq!(d.camera.unwrap().vfov_deg, 50.0);
    let d = load_toml(&write(
        "camup.toml",
        "mesh = \"builtin:furnace\"\n[camera]\nposition = [0.5, 0.5, 0.1]\nlook_at = [0.5, 0.5, 1]\nvfov_deg = 60\n",
    ))
    .unwrap();
    assert_eq!(d.camera.unwrap().up, DVec3::Y);
}

#[test]
fn several_meshes_are_concatenated_with_offsets() {
    let p = write("two.toml", &format!("meshes = [\"builtin:furnace\", {:?}]\n[materials.furnace]\ntwo_sided = true\n", cornell_obj()));
    let d: SceneDesc = load_toml(&p).unwrap();
    assert_eq!(d.objects.len(), 6 + 19);
    assert_eq!(d.materials.len(), 1 + 4);
    let floor = d.polygons.iter().find(|q| d.objects[q.object as usize].name == "floor" && q.material != 0).unwrap();
    assert!(floor.material >= 1 && floor.object >= 6);
    assert!(d.materials[0].two_sided == Some(true) && d.materials[1].two_sided.is_none());
    Scene::from_desc(d).unwrap();
}

/// Issue 9: everything two-sided but the lamp. A material's own `two_sided = false` holds
/// against the scene's `two_sided = true` (and the CLI's --two-sided, which sets the same).
#[test]
fn material_two_sided_false_keeps_an_emitter_one_sided_in_a_two_sided_scene() {
    let p = write(
        "one-sided-lamp.toml",
        &format!("two_sided = true\nmeshes = [{:?}]\n[materials.light]\ntwo_sided = false\n", cornell_obj()),
    );
    let s = Scene::from_desc(load_toml(&p).unwrap()).unwrap();
    let light = s.materials.iter().position(|m| m.name == "light").unwrap() as u32;
    let lamp: Vec<_> = s.polygons.iter().filter(|q| q.material == light).collect();
    assert!(!lamp.is_empty() && lamp.iter().all(|q| !q.back_side && !q.two_sided), "the lamp stays one-sided");
    let front = s.polygons.iter().filter(|q| q.material != light && !q.back_side).count();
    let back = s.polygons.iter().filter(|q| q.material != light && q.back_side).count();
    assert!(front >= 18 && back == front, "every other polygon has a back copy: {front} fronts, {back} backs");
}

/// A glTF whose only material has the default white base colour (1.0): unusable alone,
/// usable once the TOML file overrides its reflectance.
fn white_gltf() -> PathBuf {
    use base64::Engine as _;
    let tri: Vec<u8> = [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]].iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
    let j = serde_json::json!({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri": format!("data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&tri))}]
    });
    let p = tmp("white.gltf");
    std::fs::write(&p, serde_json::to_string_pretty(&j).unwrap()).unwrap();
    p
}

#[test]
fn gltf_base_color_of_one_is_lowered_or_overridden() {
    let g = white_gltf();
    // Without an override: lowered to MAX_REFLECTANCE with a warning naming the glTF file
    // and the material; strict mode refuses it there.
    let p = write("white-plain.toml", "mesh = \"white.gltf\"\n");
    let s = Scene::from_desc(load_toml(&p).unwrap()).unwrap();
    assert_eq!(s.materials[0].reflectance, Rgb::splat(scene::MAX_REFLECTANCE));
    let w = s.warnings.iter().find(|w| w.msg.contains("lowered")).expect("a warning");
    assert!(w.msg.contains(&format!("'paint' ({}:", g.display())), "{w}");
    let mut d = load_toml(&p).unwrap();
    d.strict = true;
    let e = Scene::from_desc(d).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:", g.display())) && e.contains("'paint'"), "{e}");
    // Overriding the reflectance sets the value wanted (no warning).
    let d = load_toml(&write("white-fixed.toml", "mesh = \"white.gltf\"\n[materials.paint]\nreflectance = [0.7, 0.7, 0.7]\n"))
        .unwrap();
    assert_eq!(d.materials[0].reflectance, Rgb::splat(0.7));
    let s = Scene::from_desc(d).unwrap();
    assert!(!s.warnings.iter().any(|w| w.msg.contains("lowered")), "{:?}", s.warnings);
}

#[test]
fn kajiya_cornell_box_lit_by_name() {
    let kajiya = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/gltf/cornell-box-kajiya/scene.gltf");
    if !kajiya.is_file() {
        eprintln!("skipped: {} is absent (../shared)", kajiya.display());
        return;
    }
    let unlit = write("kajiya-unlit.toml", &format!("mesh = {:?}\n", kajiya.display().to_string()));
    let d = load_toml(&unlit).unwrap();
    assert!(d.materials.iter().all(|m| m.emission == Rgb::ZERO));
    let lit = write(
        "kajiya.toml",
        &format!("mesh = {:?}\n[materials.light]\nemission = [17, 12, 4]\n", kajiya.display().to_string()),
    );
    let s = Scene::from_desc(load_toml(&lit).unwrap()).unwrap();
    assert_eq!(s.materials.iter().filter(|m| m.is_emitter()).count(), 1);
    let settings = Settings { mesh_size: Some(0.5), ..Default::default() };
    let solved = solve_scene(s, &settings, &NoProgress).unwrap();
    let energy = solved.energy();
    assert!(energy.emitted[0] > 0.0 && energy.absorbed[0] > 0.0, "{energy:?}");
    // Light bounces: some non-emitting element is lit.
    assert!(solved.solution.radiosity.iter().any(|b| b.x > 0.0));
}

#[test]
fn example_scene_in_the_repository_loads() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-blue-light.toml");
    let s = Scene::from_desc(load_toml(&p).unwrap()).unwrap();
    let light = s.materials.iter().find(|m| m.name == "light").unwrap();
    assert!(light.emission.z > light.emission.x);
    assert!(s.camera.is_some());
}

// ---------------------------------------------------------------- malformed input

#[test]
fn syntax_type_and_unknown_key_errors_name_line_and_column() {
    err_at("syntax.toml", "mesh = \"builtin:cornell\"\n[materials.light\nemission = [1, 1, 1]\n", 2);
    err_at("type.toml", "mesh = 3\n", 1);
    err_at("type2.toml", "mesh = \"builtin:cornell\"\ntwo_sided = \"yes\"\n", 2);
    err_at("type3.toml", "mesh = \"builtin:cornell\"\n[materials.light]\nemission = [1, 2]\n", 3);
    err_at("type4.toml", "mesh = \"builtin:cornell\"\ncamera = 7\n", 2);
    let e = err_at("unknown.toml", "mesh = \"builtin:cornell\"\n\n[materials.light]\nemision = [1, 1, 1]\n", 4);
    assert!(e.contains("emision"), "{e}");
    err_at("unknown2.toml", "mesh = \"builtin:cornell\"\n[camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nvfov = 30\n", 5);
    err_at("unknown3.toml", "mesh = \"builtin:cornell\"\nlights = 1\n", 2);
}

#[test]
fn empty_garbage_and_truncated_files_are_errors() {
    let e = err("empty.toml", "");
    assert!(e.contains("empty.toml") && e.contains("no mesh"), "{e}");
    let p = tmp("garbage.toml");
    std::fs::write(&p, [0xffu8, 0xfe, 0x00, 0x41, 0x3d, 0x5b]).unwrap();
    assert!(load_toml(&p).unwrap_err().to_string().starts_with(&format!("{}:1:", p.display())));
    let full = "mesh = \"builtin:cornell\"\n[camera]\nposition = [278, 273, -800]\nlook_at = [278, 273, 0]\nvfov_deg = 39.3\n[materials.light]\nemission = [17, 12, 4]\n";
    for n in 0..full.len() {
        let p = write("truncated.toml", &full[..n]);
        if let Ok(d) = load_toml(&p) {
            let _ = Scene::from_desc(d);
        }
    }
}

#[test]
fn missing_and_unknown_meshes_name_the_toml_line() {
    let e = err_at("missing.toml", "# comment\nmesh = \"nowhere.obj\"\n", 2);
    assert!(e.contains("nowhere.obj") && e.contains("does not exist"), "{e}");
    err_at("ext.toml", "mesh = \"missing.toml\"\n", 1);
    let e = err_at("builtin.toml", "mesh = \"builtin:nope\"\n", 1);
    assert!(e.contains("cornell, furnace"), "{e}");
    err_at("both.toml", "mesh = \"builtin:cornell\"\nmeshes = [\"builtin:cornell\"]\n", 1);
    err_at("none.toml", "meshes = []\n", 1);
    let e = err_at("camfile.toml", "mesh = \"builtin:cornell\"\ncamera = \"nope.json\"\n", 2);
    assert!(e.contains("nope.json"), "{e}");
    // A broken mesh file: the error names that file and its line.
    std::fs::write(tmp("broken.obj"), "v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap();
    let e = err("broken.toml", "mesh = \"broken.obj\"\n");
    assert!(e.starts_with(&format!("{}:3:", tmp("broken.obj").display())), "{e}");
}

#[test]
fn non_physical_values_are_rejected_with_their_line() {
    let base = "mesh = \"builtin:cornell\"\n[materials.light]\n";
    for (i, bad) in ["emission = [1, nan, 1]", "emission = [inf, 1, 1]", "emission = [-1, 0, 0]", "emission = [1e31, 0, 0]", "reflectance = [0.5, -0.1, 0]", "reflectance = [0.5, nan, 0]"]
        .iter()
        .enumerate()
    {
        if bad.contains("1e31") {
            // Too much emission is found by validation, at the override's table.
            let d = load_toml(&write(&format!("value{i}.toml"), &format!("{base}{bad}\n"))).unwrap();
            let e = Scene::from_desc(d).unwrap_err().to_string();
            assert!(e.starts_with(&format!("{}:2:", tmp(&format!("value{i}.toml")).display())) && e.contains("above 1e30"), "{e}");
            continue;
        }
        err_at(&format!("value{i}.toml"), &format!("{base}{bad}\n"), 3);
    }
    // Reflectance 1: lowered with a warning, refused in strict mode at the override.
    let p = write("refl1.toml", &format!("{base}reflectance = [1, 0, 0]\n"));
    let s = Scene::from_desc(load_toml(&p).unwrap()).unwrap();
    assert!(s.warnings.iter().any(|w| w.msg.contains("'light'") && w.msg.contains("lowered to 0.95")), "{:?}", s.warnings);
    let mut d = load_toml(&p).unwrap();
    d.strict = true;
    let e = Scene::from_desc(d).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:2:", p.display())) && e.contains("'light'"), "{e}");
    let e = err_at("unknown-mat.toml", "mesh = \"builtin:cornell\"\n\n[materials.lamp]\nemission = [1, 1, 1]\n", 3);
    assert!(e.contains("lamp") && e.contains("green, light, red, white"), "{e}");
    // Camera values.
    let cam = "mesh = \"builtin:cornell\"\n[camera]\nposition = [0, 0, 0]\n";
    err_at("cam1.toml", &format!("{cam}look_at = [0, 0, 0]\nvfov_deg = 40\n"), 2);
    err_at("cam2.toml", &format!("{cam}look_at = [0, 0, 1]\nvfov_deg = 180\n"), 2);
    err_at("cam3.toml", &format!("{cam}look_at = [0, 0, nan]\nvfov_deg = 40\n"), 2);
    err_at("cam4.toml", &format!("{cam}look_at = [0, 1, 0]\nvfov_deg = 40\n"), 2);
}

#[test]
fn thermal_bands_are_read_and_checked_at_their_line() {
    let mtl = "newmtl hot\nKd 0.5 0.5 0.5\n";
    let obj = "mtllib b.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl hot\nf 1 2 3\n";
    std::fs::write(tmp("b.mtl"), mtl).unwrap();
    std::fs::write(tmp("b.obj"), obj).unwrap();
    let good = write("bands.toml", "mesh = \"b.obj\"\n[thermal]\nband_edges = [3.0, 8.0]\n[materials.hot]\nemissivity = [0.1, 0.5, 0.9]\ntemperature = 500\n");
    let desc = radiosity::scene::load(good.to_str().unwrap()).unwrap();
    assert_eq!(desc.band_edges, vec![3.0, 8.0]);
    assert_eq!(desc.materials[0].thermal.as_ref().unwrap().band_emissivity, vec![0.1, 0.5, 0.9]);
    let scene = radiosity::scene::Scene::from_desc(desc).unwrap();
    assert_eq!(scene.materials[0].thermal.as_ref().unwrap().band_emissivity, vec![0.1, 0.5, 0.9]);
    // Edges that go down, at the [thermal] table; one value in a list, at the value.
    let e = err_at("bands-down.toml", "mesh = \"b.obj\"\n[thermal]\nband_edges = [8.0, 3.0]\n", 2);
    assert!(e.contains("band_edges") && e.contains("increasing"), "{e}");
    let e = err_at("bands-one.toml", "mesh = \"b.obj\"\n[materials.hot]\nemissivity = [0.5]\ntemperature = 500\n", 3);
    assert!(e.contains("one per band"), "{e}");
    // A band emissivity out of range is named by validation.
    let bad = write("bands-range.toml", "mesh = \"b.obj\"\n[materials.hot]\nemissivity = [0.5, 1.5]\ntemperature = 500\n");
    let e = radiosity::scene::Scene::from_desc(radiosity::scene::load(bad.to_str().unwrap()).unwrap()).unwrap_err().to_string();
    assert!(e.contains("band emissivity 1.5"), "{e}");
}
