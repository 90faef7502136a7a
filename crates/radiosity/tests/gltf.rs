//! glTF/GLB reader: real files, synthetic files built here (so transforms, winding, emissive
//! strength and errors are asserted with numbers), and malformed input (never a panic).

use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::DVec3;
use radiosity::scene::{self, gltf::load_gltf, Scene, SceneDesc};
use radiosity::Rgb;
use serde_json::{json, Value};

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("gltf-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn shared() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
    p.is_dir().then_some(p)
}

fn f32_bytes(v: &[[f32; 3]]) -> Vec<u8> {
    v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect()
}

/// A one-mesh document: accessor 0 = positions (bufferView 0), accessor 1 = u16 indices
/// (bufferView 1) when given; material 0 with reflectance 0.5; node 0 draws mesh 0.
fn doc(positions: &[[f32; 3]], indices: Option<&[u16]>) -> (Value, Vec<u8>) {
    let mut bin = f32_bytes(positions);
    let plen = bin.len();
    let mut accessors = vec![json!({
        "bufferView": 0, "componentType": 5126, "count": positions.len(), "type": "VEC3",
        "min": [0, 0, 0], "max": [1, 1, 1]
    })];
    let mut views = vec![json!({"buffer": 0, "byteOffset": 0, "byteLength": plen})];
    let mut prim = json!({"attributes": {"POSITION": 0}, "material": 0});
    if let Some(idx) = indices {
        let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
        views.push(json!({"buffer": 0, "byteOffset": plen, "byteLength": bytes.len()}));
        accessors.push(json!({"bufferView": 1, "componentType": 5123, "count": idx.len(), "type": "SCALAR"}));
        prim["indices"] = json!(1);
        bin.extend(bytes);
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let j = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "thing"}],
        "meshes": [{"name": "m", "primitives": [prim]}],
        "materials": [{"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]}}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}]
    });
    (j, bin)
}

/// Writes `.gltf` with the buffer embedded as a data: URI (pretty-printed JSON, so errors
/// have meaningful lines).
fn write_embedded(name: &str, mut j: Value, bin: &[u8]) -> PathBuf {
    if j["buffers"][0].get("uri").is_none() {
        let b64 = base64::engine::general_purpose::STANDARD.encode(bin);
        j["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{b64}"));
    }
    let p = tmp(name);
    std::fs::write(&p, serde_json::to_string_pretty(&j).unwrap()).unwrap();
    p
}

fn glb_bytes(j: &Value, bin: &[u8]) -> Vec<u8> {
    let mut js = serde_json::to_vec(j).unwrap();
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    let total = 12 + 8 + js.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((js.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(js);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

fn write_glb(name: &str, j: &Value, bin: &[u8]) -> PathBuf {
    let p = tmp(name);
    std::fs::write(&p, glb_bytes(j, bin)).unwrap();
    p
}

fn load(p: &Path) -> radiosity::Result<SceneDesc> {
    load_gltf(p)
}

const TRI: [[f32; 3]; 3] = [[0., 0., 1.], [1., 0., 1.], [0., 1., 1.]];

fn err_of(p: &Path) -> String {
    match load(p) {
        Ok(_) => panic!("{} loaded but should not", p.display()),
        Err(e) => e.to_string(),
    }
}

// ---------------------------------------------------------------- real files

#[test]
fn khronos_box_embedded() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/Box-Embedded.gltf");
    let d = load(&p).unwrap();
    assert_eq!(d.polygons.len(), 12);
    assert_eq!(d.objects.len(), 1);
    assert_eq!(d.objects[0].name, "Mesh");
    assert_eq!(d.materials.len(), 1);
    assert!((d.materials[0].reflectance - Rgb::new(0.8, 0.0, 0.0)).abs().max_element() < 1e-6);
    let s = Scene::from_desc(d).unwrap();
    // A unit cube centred at the origin, faces outwards (glTF fronts are counter-clockwise).
    assert!((s.total_area() - 6.0).abs() < 1e-9, "area {}", s.total_area());
    for p in &s.polygons {
        assert!(p.normal.dot(p.centroid()) > 0.49, "inward face {:?}", p.normal);
    }
    // The parent's matrix turns the mesh's +Y into −Z; a cube is symmetric, so check bounds.
    let (lo, hi) = s.bounds();
    assert!((lo + DVec3::splat(0.5)).abs().max_element() < 1e-6 && (hi - DVec3::splat(0.5)).abs().max_element() < 1e-6);
}

#[test]
fn kajiya_cornell_box_from_shared() {
    let Some(sh) = shared() else {
        eprintln!("skipped: ../shared is absent (kajiya Cornell box is read from there)");
        return;
    };
    let p = sh.join("scenes/gltf/cornell-box-kajiya/scene.gltf");
    let d = load(&p).unwrap();
    assert_eq!(d.polygons.len(), 32);
    let mut names: Vec<&str> = d.materials.iter().map(|m| m.name.as_str()).collect();
    names.sort();
    assert_eq!(names, ["backWall", "ceiling", "floor", "leftWall", "light", "rightWall", "shortBox", "tallBox"]);
    assert!(d.materials.iter().all(|m| m.two_sided == Some(true) && m.emission == Rgb::ZERO));
    let light = d.materials.iter().find(|m| m.name == "light").unwrap();
    // The material's line in the JSON text.
    let text = std::fs::read_to_string(&p).unwrap();
    let line = light.loc.as_ref().unwrap().line.unwrap();
    assert!(text.lines().skip(line - 1).take(3).any(|l| l.contains("\"light\"")), "line {line}");
    let s = Scene::from_desc(d).unwrap();
    // Blender's Z-up box rotated by the node's −90° about X into glTF's Y-up: about 2 units tall.
    let (lo, hi) = s.bounds();
    eprintln!("kajiya bounds {lo} {hi}");
    assert!((hi.y - lo.y - 2.0).abs() < 0.05, "{lo} {hi}");
}

// ---------------------------------------------------------------- transforms and winding

#[test]
fn node_hierarchy_transforms_apply_parent_after_child() {
    let (mut j, bin) = doc(&TRI, None);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    j["nodes"] = json!([
        {"name": "parent", "translation": [10, 0, 0], "children": [1]},
        {"name": "child", "mesh": 0, "rotation": [0, 0, h, h], "scale": [2, 2, 2]}
    ]);
    let d = load(&write_embedded("hier.gltf", j, &bin)).unwrap();
    assert_eq!(d.objects.len(), 1);
    assert_eq!(d.objects[0].name, "child");
    // World = T(10,0,0) · R_z(90°) · S(2): (x, y, z) → (10 − 2y, 2x, 2z).
    let want = [DVec3::new(10., 0., 2.), DVec3::new(10., 2., 2.), DVec3::new(8., 0., 2.)];
    for (v, w) in d.polygons[0].vertices.iter().zip(want) {
        assert!((*v - w).length() < 1e-6, "{v} vs {w}");
    }
}

#[test]
fn matrix_transform_and_instancing() {
    let (mut j, bin) = doc(&TRI, None);
    j["nodes"] = json!([
        {"mesh": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 5,6,7,1]},
        {"mesh": 0}
    ]);
    j["scenes"] = json!([{"nodes": [0, 1]}]);
    let d = load(&write_embedded("matrix.gltf", j, &bin)).unwrap();
    assert_eq!(d.polygons.len(), 2);
    assert_eq!(d.objects.len(), 2);
    assert_eq!(d.objects[0].name, "m", "unnamed node: named after its mesh");
    assert!((d.polygons[0].vertices[0] - DVec3::new(5., 6., 8.)).length() < 1e-6);
    assert!((d.polygons[1].vertices[0] - DVec3::new(0., 0., 1.)).length() < 1e-6);
}

#[test]
fn unnamed_node_and_mesh_get_node_index() {
    let (mut j, bin) = doc(&TRI, None);
    j["nodes"] = json!([{}, {"mesh": 0}]);
    j["scenes"] = json!([{"nodes": [0, 1]}]);
    j["meshes"][0].as_object_mut().unwrap().remove("name");
    let d = load(&write_embedded("noname.gltf", j, &bin)).unwrap();
    assert_eq!(d.objects[0].name, "node1");
}

#[test]
fn counter_clockwise_is_front_and_mirrors_flip_winding() {
    // The triangle at z = 1 faces +Z (away from the origin).
    let (j, bin) = doc(&TRI, None);
    let s = Scene::from_desc(load(&write_embedded("ccw.gltf", j.clone(), &bin)).unwrap()).unwrap();
    assert!(s.polygons[0].normal.z > 0.999);
    // Mirrored through z = 0 it lies at z = −1 and must still face away from the origin.
    let mut jm = j;
    jm["nodes"][0]["scale"] = json!([1, 1, -1]);
    let s = Scene::from_desc(load(&write_embedded("mirror.gltf", jm, &bin)).unwrap()).unwrap();
    assert!((s.polygons[0].vertices[0].z + 1.0).abs() < 1e-9);
    assert!(s.polygons[0].normal.z < -0.999, "{}", s.polygons[0].normal);
}

#[test]
fn strips_and_fans_become_consistently_wound_triangles() {
    // A unit square in z = 0 as a strip (0,1,2,3) zig-zag and as a fan; all fronts +Z.
    let strip: [[f32; 3]; 4] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]];
    let (mut j, bin) = doc(&strip, None);
    j["meshes"][0]["primitives"][0]["mode"] = json!(5);
    let s = Scene::from_desc(load(&write_embedded("strip.gltf", j, &bin)).unwrap()).unwrap();
    assert_eq!(s.polygons.len(), 2);
    assert!(s.polygons.iter().all(|p| p.normal.z > 0.999));
    assert!((s.total_area() - 1.0).abs() < 1e-12);

    let fan: [[f32; 3]; 5] = [[0.5, 0.5, 0.], [0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    let (mut j, bin) = doc(&fan, None);
    j["meshes"][0]["primitives"][0]["mode"] = json!(6);
    let s = Scene::from_desc(load(&write_embedded("fan.gltf", j, &bin)).unwrap()).unwrap();
    assert_eq!(s.polygons.len(), 3);
    assert!(s.polygons.iter().all(|p| p.normal.z > 0.999));
    assert!((s.total_area() - 0.75).abs() < 1e-12);

    // Strip with a restart (repeated index) is skipped silently.
    let (mut j, bin) = doc(&strip, Some(&[0, 1, 2, 3, 3, 0, 0, 1, 2]));
    j["meshes"][0]["primitives"][0]["mode"] = json!(5);
    let d = load(&write_embedded("strip-restart.gltf", j, &bin)).unwrap();
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
}

#[test]
fn indexed_triangles_and_u8_u32_indices() {
    let quad: [[f32; 3]; 4] = [[0., 0., 0.], [2., 0., 0.], [2., 2., 0.], [0., 2., 0.]];
    let (j, bin) = doc(&quad, Some(&[0, 1, 2, 0, 2, 3]));
    let s = Scene::from_desc(load(&write_embedded("indexed.gltf", j.clone(), &bin)).unwrap()).unwrap();
    assert!((s.total_area() - 4.0).abs() < 1e-12);
    // Same indices as u8 and u32.
    for (ct, bytes) in [
        (5121, vec![0u8, 1, 2, 0, 2, 3]),
        (5125, [0u32, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>()),
    ] {
        let mut j2 = j.clone();
        let mut bin2 = f32_bytes(&quad);
        let off = bin2.len();
        bin2.extend(&bytes);
        while bin2.len() % 4 != 0 {
            bin2.push(0);
        }
        j2["bufferViews"][1] = json!({"buffer": 0, "byteOffset": off, "byteLength": bytes.len()});
        j2["accessors"][1]["componentType"] = json!(ct);
        j2["buffers"][0]["byteLength"] = json!(bin2.len());
        let s = Scene::from_desc(load(&write_embedded(&format!("idx{ct}.gltf"), j2, &bin2)).unwrap()).unwrap();
        assert!((s.total_area() - 4.0).abs() < 1e-12);
    }
}

#[test]
fn interleaved_stride_and_sparse_positions() {
    // Positions interleaved with 4 bytes of padding (stride 16), then a sparse override
    // that moves vertex 2 from (0,1,1) to (0,3,1).
    let mut bin = Vec::new();
    for p in TRI {
        bin.extend(f32_bytes(&[p]));
        bin.extend([0u8; 4]);
    }
    let sparse_at = bin.len();
    bin.extend(2u16.to_le_bytes());
    bin.extend([0u8; 2]);
    let values_at = bin.len();
    bin.extend(f32_bytes(&[[0., 3., 1.]]));
    let (mut j, _) = doc(&TRI, None);
    j["bufferViews"] = json!([
        {"buffer": 0, "byteOffset": 0, "byteLength": 48, "byteStride": 16},
        {"buffer": 0, "byteOffset": sparse_at, "byteLength": 2},
        {"buffer": 0, "byteOffset": values_at, "byteLength": 12}
    ]);
    j["accessors"][0]["sparse"] = json!({
        "count": 1,
        "indices": {"bufferView": 1, "componentType": 5123},
        "values": {"bufferView": 2}
    });
    j["buffers"][0]["byteLength"] = json!(bin.len());
    let d = load(&write_embedded("sparse.gltf", j, &bin)).unwrap();
    let v = &d.polygons[0].vertices;
    assert_eq!(v[1], DVec3::new(1., 0., 1.));
    assert_eq!(v[2], DVec3::new(0., 3., 1.));
}

#[test]
fn default_scene_choice_and_files_without_scenes() {
    // "scene": 1 draws the second scene only.
    let (mut j, bin) = doc(&TRI, None);
    j["nodes"] = json!([{"mesh": 0, "name": "a"}, {"mesh": 0, "name": "b", "translation": [0, 0, 1]}]);
    j["scenes"] = json!([{"nodes": [0]}, {"nodes": [1]}]);
    j["scene"] = json!(1);
    let d = load(&write_embedded("scene1.gltf", j.clone(), &bin)).unwrap();
    assert_eq!(d.objects.iter().map(|o| o.name.as_str()).collect::<Vec<_>>(), ["b"]);
    // No "scene": the first.
    j.as_object_mut().unwrap().remove("scene");
    let d = load(&write_embedded("scene0.gltf", j.clone(), &bin)).unwrap();
    assert_eq!(d.objects[0].name, "a");
    // No scenes at all: every root node.
    j.as_object_mut().unwrap().remove("scenes");
    j["nodes"][0]["children"] = json!([1]);
    let d = load(&write_embedded("noscenes.gltf", j, &bin)).unwrap();
    assert_eq!(d.objects.len(), 2);
    assert!((d.polygons[1].vertices[0].z - 2.0).abs() < 1e-9, "child under its parent");
}

#[test]
fn quantized_normalized_positions() {
    // KHR_mesh_quantization: unsigned-short normalized VEC3 positions, 8-byte stride.
    let q: [[u16; 3]; 3] = [[0, 0, 65535], [65535, 0, 65535], [0, 32768, 65535]];
    let bin: Vec<u8> = q.iter().flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()).chain([0u8, 0])).collect();
    let (mut j, _) = doc(&TRI, None);
    j["accessors"][0]["componentType"] = json!(5123);
    j["accessors"][0]["normalized"] = json!(true);
    j["bufferViews"][0] = json!({"buffer": 0, "byteLength": 24, "byteStride": 8});
    j["buffers"][0]["byteLength"] = json!(24);
    j["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    j["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    let d = load(&write_embedded("quantized.gltf", j, &bin)).unwrap();
    let v = &d.polygons[0].vertices;
    assert_eq!(v[0], DVec3::new(0., 0., 1.));
    assert_eq!(v[1], DVec3::new(1., 0., 1.));
    assert!((v[2].y - 32768.0 / 65535.0).abs() < 1e-12);
}

// ---------------------------------------------------------------- materials

#[test]
fn emissive_strength_multiplies_emissive_factor() {
    let (mut j, bin) = doc(&TRI, None);
    j["materials"][0]["emissiveFactor"] = json!([1.0, 0.5, 0.25]);
    j["materials"][0]["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}});
    j["materials"][0]["doubleSided"] = json!(true);
    j["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
    let d = load(&write_embedded("emissive.gltf", j, &bin)).unwrap();
    let m = &d.materials[0];
    assert_eq!(m.emission, Rgb::new(4.0, 2.0, 1.0));
    assert_eq!(m.reflectance, Rgb::splat(0.5));
    assert_eq!(m.two_sided, Some(true));
    let s = Scene::from_desc(d).unwrap();
    assert_eq!(s.polygons.len(), 2, "double-sided: a back copy");
    assert!((s.materials[0].exitance().x - 4.0 * std::f64::consts::PI).abs() < 1e-12);
}

#[test]
fn missing_base_color_gets_default_with_warning() {
    let (mut j, bin) = doc(&TRI, None);
    j["materials"][0] = json!({"name": "plain"});
    let d = load(&write_embedded("nobase.gltf", j, &bin)).unwrap();
    assert_eq!(d.materials[0].reflectance, Rgb::splat(0.8));
    assert!(d.warnings.iter().any(|w| w.msg.contains("'plain'") && w.msg.contains("0.8")), "{:?}", d.warnings);

    let (mut j, bin) = doc(&TRI, None);
    j["meshes"][0]["primitives"][0].as_object_mut().unwrap().remove("material");
    j.as_object_mut().unwrap().remove("materials");
    let d = load(&write_embedded("nomat.gltf", j, &bin)).unwrap();
    assert_eq!(d.materials.len(), 1);
    assert_eq!(d.materials[0].name, "default");
    assert_eq!(d.materials[0].reflectance, Rgb::splat(0.8));
    assert!(!d.warnings.is_empty());
}

#[test]
fn base_color_of_one_is_capped_with_one_warning_or_refused_when_strict() {
    let (mut j, bin) = doc(&TRI, None);
    j["materials"] = json!([
        {"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}},
        {"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}}
    ]);
    j["meshes"][0]["primitives"][0]["material"] = json!(1);
    let p = write_embedded("white.gltf", j.clone(), &bin);
    // Default: lowered to MAX_REFLECTANCE, one warning naming the material and its line.
    let s = Scene::from_desc(load(&p).unwrap()).unwrap();
    assert_eq!(s.materials[0].reflectance, Rgb::splat(scene::MAX_REFLECTANCE));
    let capped: Vec<_> = s.warnings.iter().filter(|w| w.msg.contains("lowered to")).collect();
    assert_eq!(capped.len(), 1, "{:?}", s.warnings);
    assert!(capped[0].msg.contains("'white'") && capped[0].msg.contains(&format!("{}:", p.display())), "{}", capped[0]);
    // Strict: an error at the material's line.
    let mut d = load(&p).unwrap();
    d.strict = true;
    let e = Scene::from_desc(d).unwrap_err().to_string();
    let text = std::fs::read_to_string(&p).unwrap();
    let line = text.lines().position(|l| l.contains("\"white\"")).unwrap() + 1;
    // The element starts at its `{`, a line or two above its name.
    let prefix = format!("{}:", p.display());
    assert!(e.starts_with(&prefix), "{e}");
    let l: usize = e[prefix.len()..].split(':').next().unwrap().parse().unwrap();
    assert!(l <= line && line - l <= 3, "error at line {l}, material name at {line}: {e}");
    assert!(e.contains("'white'") && e.contains("[0, 1)"), "{e}");
    // GLB: names file and material.
    let mut d = load(&write_glb("white.glb", &j, &bin)).unwrap();
    d.strict = true;
    let e = Scene::from_desc(d).unwrap_err().to_string();
    assert!(e.contains("white.glb") && e.contains("'white'"), "{e}");
    // Negative stays an error at load.
    j["materials"][1]["pbrMetallicRoughness"]["baseColorFactor"] = json!([-0.1, 0.5, 0.5, 1]);
    let e = err_of(&write_embedded("negbase.gltf", j, &bin));
    assert!(e.contains("negbase.gltf:") && e.contains("'white'") && e.contains("negative"), "{e}");
}

#[test]
fn position_accessor_must_be_float_vec3() {
    // UNSIGNED_INT positions (the audit's garbage-in case): refused, naming the accessor's
    // line, the mesh and primitive, and the rule.
    let u: Vec<u8> = [[0u32, 0, 1], [1, 0, 1], [0, 1, 1]].iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
    let (mut j, _) = doc(&TRI, None);
    j["accessors"][0]["componentType"] = json!(5125);
    let p = write_embedded("uint-pos.gltf", j.clone(), &u);
    let e = err_of(&p);
    let text = std::fs::read_to_string(&p).unwrap();
    let acc_line = text.lines().position(|l| l.contains("\"accessors\"")).unwrap() + 1;
    assert!(e.starts_with(&format!("{}:{}:", p.display(), acc_line + 1)), "{e}");
    assert!(e.contains("mesh 'm' (meshes[0]) primitive 0") && e.contains("U32") && e.contains("FLOAT"), "{e}");
    // Even with KHR_mesh_quantization, UNSIGNED_INT is not allowed.
    j["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    let e = err_of(&write_embedded("uint-pos-q.gltf", j, &u));
    assert!(e.contains("U32") && e.contains("KHR_mesh_quantization"), "{e}");
    // UNSIGNED_SHORT without the extension: refused; normalized FLOAT: refused.
    let (mut j, bin) = doc(&TRI, None);
    j["accessors"][0]["componentType"] = json!(5123);
    let e = err_of(&write_embedded("u16-pos.gltf", j, &bin));
    assert!(e.contains("U16") && e.contains("KHR_mesh_quantization"), "{e}");
    let (mut j, bin) = doc(&TRI, None);
    j["accessors"][0]["normalized"] = json!(true);
    let e = err_of(&write_embedded("normfloat-pos.gltf", j, &bin));
    assert!(e.contains("normalized F32"), "{e}");
    // Index accessors: FLOAT, signed or normalized indices are refused; out of range too.
    for (name, ct, norm, want) in [("f32-idx.gltf", 5126, false, "F32"), ("i16-idx.gltf", 5122, false, "I16"), ("norm-idx.gltf", 5123, true, "normalized")] {
        let (mut j, bin) = doc(&TRI, Some(&[0, 1, 2, 0, 0, 0]));
        j["accessors"][1]["componentType"] = json!(ct);
        j["accessors"][1]["normalized"] = json!(norm);
        if ct == 5126 {
            j["accessors"][1]["count"] = json!(3);
        }
        let e = err_of(&write_embedded(name, j, &bin));
        assert!(e.contains(name) && e.contains("index accessor 1") && e.contains(want), "{name}: {e}");
    }
    let (j, bin) = doc(&TRI, Some(&[0, 1, 3]));
    let e = err_of(&write_embedded("idx-range.gltf", j, &bin));
    assert!(e.contains("vertex index 3 is out of range"), "{e}");
}

#[test]
fn punctual_lights_are_placed_by_their_nodes() {
    use radiosity::scene::LightKind;
    let (mut j, bin) = doc(&TRI, None);
    j["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    j["extensions"] = json!({"KHR_lights_punctual": {"lights": [
        {"type": "point", "name": "bulb", "color": [1.0, 0.5, 0.25], "intensity": 8.0, "range": 5.0},
        {"type": "spot", "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
        {"type": "directional", "intensity": 3.0},
        {"type": "area"},
        {"type": "point", "name": "unplaced"}
    ]}});
    j["scenes"][0]["nodes"] = json!([0, 1]);
    // Rotation −90° about X turns −Z (where a light points) into −Y.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    j["nodes"] = json!([
        {"mesh": 0, "name": "thing"},
        {"name": "rig", "translation": [1.0, 2.0, 3.0], "children": [2, 3, 4, 5]},
        {"extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"rotation": [-s, 0.0, 0.0, s], "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"scale": [2.0, 2.0, 2.0], "extensions": {"KHR_lights_punctual": {"light": 2}}},
        {"extensions": {"KHR_lights_punctual": {"light": 3}}}
    ]);
    let p = write_embedded("punctual.gltf", j.clone(), &bin);
    let d = load(&p).unwrap();
    assert_eq!(d.lights.len(), 3, "{:?}", d.lights);
    assert_eq!(d.lights[0].name, "bulb");
    assert_eq!(d.lights[0].kind, LightKind::Point { position: DVec3::new(1.0, 2.0, 3.0) });
    assert_eq!(d.lights[0].intensity, Rgb::new(8.0, 4.0, 2.0));
    let LightKind::Spot { position, direction, inner_cone, outer_cone } = d.lights[1].kind else { panic!("{:?}", d.lights[1]) };
    assert_eq!(position, DVec3::new(1.0, 2.0, 3.0));
    assert!((direction - DVec3::NEG_Y).length() < 1e-6, "{direction}");
    assert!((inner_cone - 0.2).abs() < 1e-12 && (outer_cone - 0.5).abs() < 1e-12);
    let LightKind::Directional { direction } = d.lights[2].kind else { panic!("{:?}", d.lights[2]) };
    assert!((direction.normalize() - DVec3::NEG_Z).length() < 1e-12);
    assert!(d.warnings.iter().any(|w| w.msg.contains("range is ignored")), "{:?}", d.warnings);
    assert_eq!(d.ignored_lights.len(), 1, "{:?}", d.ignored_lights);
    assert!(d.ignored_lights[0].contains("\"area\""), "{:?}", d.ignored_lights);
    // A scene lit only by them is lit; validation normalises the directional light.
    let s = Scene::from_desc(d).unwrap();
    s.check_emits().unwrap();
    let LightKind::Directional { direction } = s.lights[2].kind else { unreachable!() };
    assert!((direction - DVec3::NEG_Z).length() < 1e-12);

    // Out of range, and a cone that glTF forbids (outer > π/2), are errors naming the file.
    j["nodes"][2]["extensions"]["KHR_lights_punctual"]["light"] = json!(9);
    let e = err_of(&write_embedded("punctual-range.gltf", j.clone(), &bin));
    assert!(e.contains("KHR_lights_punctual light 9 is out of range (there are 5)"), "{e}");
    j["nodes"][2]["extensions"]["KHR_lights_punctual"]["light"] = json!(1);
    j["extensions"]["KHR_lights_punctual"]["lights"][1]["spot"]["outerConeAngle"] = json!(2.0);
    let p = write_embedded("punctual-cone.gltf", j, &bin);
    let e = Scene::from_desc(load(&p).unwrap()).unwrap_err().to_string();
    assert!(e.starts_with(&p.display().to_string()) && e.contains("must satisfy 0 ≤ inner < outer ≤ 90°"), "{e}");
}

#[test]
fn lights_of_no_kind_we_know_leave_the_scene_dark_and_say_so() {
    let (mut j, bin) = doc(&TRI, None);
    j["extensions"] = json!({"KHR_lights_punctual": {"lights": [{"type": "area"}]}});
    j["nodes"][0]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}});
    let p = write_embedded("punctual-dark.gltf", j, &bin);
    let s = Scene::from_desc(load(&p).unwrap()).unwrap();
    let e = s.check_emits().unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}: no surface emits light", p.display())), "{e}");
    assert!(e.contains("light 'light 0' of type \"area\" is ignored"), "{e}");
}

#[test]
fn external_buffer_that_is_not_a_regular_file_is_refused() {
    let (mut j, bin) = doc(&TRI, None);
    let dev = tmp("zero.bin");
    let _ = std::fs::remove_file(&dev);
    std::os::unix::fs::symlink("/dev/zero", &dev).unwrap();
    j["buffers"][0]["uri"] = json!("zero.bin");
    let e = err_of(&write_embedded("zero-buffer.gltf", j.clone(), &bin));
    assert!(e.contains("zero-buffer.gltf:") && e.contains("zero.bin") && e.contains("is not a regular file"), "{e}");
    std::fs::create_dir_all(tmp("dir.bin")).unwrap();
    j["buffers"][0]["uri"] = json!("dir.bin");
    let e = err_of(&write_embedded("dir-buffer.gltf", j, &bin));
    assert!(e.contains("dir.bin") && e.contains("is a directory"), "{e}");
    // The glTF itself.
    let dev = tmp("zero.gltf");
    let _ = std::fs::remove_file(&dev);
    std::os::unix::fs::symlink("/dev/zero", &dev).unwrap();
    let e = err_of(&dev);
    assert!(e.contains("zero.gltf") && e.contains("is not a regular file"), "{e}");
}

#[test]
fn unused_materials_are_not_checked_or_kept() {
    let (mut j, bin) = doc(&TRI, None);
    j["materials"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "unused", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}}));
    let d = load(&write_embedded("unused.gltf", j, &bin)).unwrap();
    assert_eq!(d.materials.len(), 1);
}

#[test]
fn negative_or_infinite_emission_is_rejected_by_validation() {
    let (mut j, bin) = doc(&TRI, None);
    j["materials"][0]["emissiveFactor"] = json!([1.0, -0.5, 0.0]);
    let d = load(&write_embedded("negemit.gltf", j.clone(), &bin)).unwrap();
    let e = Scene::from_desc(d).unwrap_err().to_string();
    assert!(e.contains("negemit.gltf:") && e.contains("non-negative"), "{e}");
    j["materials"][0]["emissiveFactor"] = json!([1e39, 0.0, 0.0]); // f32 overflow → inf
    let d = load(&write_embedded("infemit.gltf", j.clone(), &bin)).unwrap();
    assert!(Scene::from_desc(d).is_err());
    // Finite but above MAX_EMISSION (exitance × area would overflow downstream).
    j["materials"][0]["emissiveFactor"] = json!([1e35, 0.0, 0.0]);
    let d = load(&write_embedded("hugeemit.gltf", j, &bin)).unwrap();
    let e = Scene::from_desc(d).unwrap_err().to_string();
    assert!(e.contains("hugeemit.gltf:") && e.contains("above 1e30"), "{e}");
}

// ---------------------------------------------------------------- camera, containers, buffers

#[test]
fn perspective_camera_on_a_node() {
    let (mut j, bin) = doc(&TRI, None);
    j["cameras"] = json!([{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}]);
    j["nodes"].as_array_mut().unwrap().push(json!({"camera": 0, "translation": [0, 0, 5]}));
    j["scenes"] = json!([{"nodes": [0, 1]}]);
    let d = load(&write_embedded("camera.gltf", j, &bin)).unwrap();
    let c = d.camera.unwrap();
    assert!((c.position - DVec3::new(0., 0., 5.)).length() < 1e-9);
    assert!((c.look_at - DVec3::new(0., 0., 4.)).length() < 1e-9);
    assert!((c.up - DVec3::Y).length() < 1e-9);
    assert!((c.vfov_deg - 0.5f64.to_degrees()).abs() < 1e-9);
}

#[test]
fn glb_and_external_buffer_read_the_same_geometry() {
    let quad: [[f32; 3]; 4] = [[0., 0., 0.], [2., 0., 0.], [2., 2., 0.], [0., 2., 0.]];
    let (j, bin) = doc(&quad, Some(&[0, 1, 2, 0, 2, 3]));
    let a = load(&write_embedded("same.gltf", j.clone(), &bin)).unwrap();
    let b = load(&write_glb("same.glb", &j, &bin)).unwrap();
    std::fs::write(tmp("my buffer.bin"), &bin).unwrap();
    let mut je = j.clone();
    je["buffers"][0]["uri"] = json!("my%20buffer.bin");
    let p = tmp("external.gltf");
    std::fs::write(&p, serde_json::to_string_pretty(&je).unwrap()).unwrap();
    let c = load(&p).unwrap();
    let verts = |d: &SceneDesc| d.polygons.iter().map(|p| p.vertices.clone()).collect::<Vec<_>>();
    assert_eq!(a.polygons.len(), 2);
    assert_eq!(verts(&a), verts(&b));
    assert_eq!(verts(&a), verts(&c));
    // scene::load dispatches by extension.
    assert_eq!(scene::load(p.to_str().unwrap()).unwrap().polygons.len(), 2);
}

#[test]
fn points_and_lines_are_skipped_with_a_warning() {
    let (mut j, bin) = doc(&TRI, None);
    let mut prims = j["meshes"][0]["primitives"].clone();
    let mut lines = prims[0].clone();
    lines["mode"] = json!(1);
    prims.as_array_mut().unwrap().push(lines);
    j["meshes"][0]["primitives"] = prims;
    let d = load(&write_embedded("lines.gltf", j.clone(), &bin)).unwrap();
    assert_eq!(d.polygons.len(), 1);
    assert!(d.warnings.iter().any(|w| w.msg.contains("no area")), "{:?}", d.warnings);
    // Only lines: nothing to light.
    j["meshes"][0]["primitives"] = json!([{"attributes": {"POSITION": 0}, "mode": 0}]);
    let e = err_of(&write_embedded("points.gltf", j, &bin));
    assert!(e.contains("no triangles"), "{e}");
}

// ---------------------------------------------------------------- malformed input

#[test]
fn empty_garbage_and_truncated_files_are_errors() {
    let p = tmp("empty.gltf");
    std::fs::write(&p, b"").unwrap();
    let e = err_of(&p);
    assert!(e.starts_with(&format!("{}:1:", p.display())), "{e}");
    let p = tmp("garbage.glb");
    std::fs::write(&p, [0xffu8, 0x00, 0x13, 0x37, 0x42]).unwrap();
    assert!(err_of(&p).contains("garbage.glb"));

    // Every prefix of a valid GLB and of a valid .gltf.
    let (j, bin) = doc(&TRI, Some(&[0, 1, 2]));
    let glb = glb_bytes(&j, &bin);
    let p = tmp("truncated.glb");
    for n in 0..glb.len() {
        std::fs::write(&p, &glb[..n]).unwrap();
        let e = err_of(&p);
        assert!(e.contains("truncated.glb"), "{n}: {e}");
    }
    let full = write_embedded("full.gltf", j, &bin);
    let text = std::fs::read(&full).unwrap();
    let p = tmp("truncated.gltf");
    for n in (0..text.len() - 1).step_by(7) {
        std::fs::write(&p, &text[..n]).unwrap();
        assert!(load(&p).is_err(), "prefix {n} loaded");
    }
}

#[test]
fn random_byte_corruption_never_panics() {
    let (j, bin) = doc(&[[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]], Some(&[0, 1, 2, 2, 1, 3]));
    let glb = glb_bytes(&j, &bin);
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let p = Path::new("fuzz.glb");
    for _ in 0..3000 {
        let mut b = glb.clone();
        for _ in 0..1 + next() % 4 {
            let i = (next() % b.len() as u64) as usize;
            b[i] = next() as u8;
        }
        // Parse from memory: external buffers are refused.
        let r = radiosity::scene::gltf::parse_gltf(&b, p, |_| Err(std::io::ErrorKind::NotFound.into()));
        if let Ok(d) = r {
            let _ = Scene::from_desc(d);
        }
    }
}

#[test]
fn invalid_json_and_wrong_types_name_line_and_column() {
    let p = tmp("syntax.gltf");
    std::fs::write(&p, "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [,]\n}\n").unwrap();
    let e = err_of(&p);
    assert!(e.starts_with(&format!("{}:3:", p.display())), "{e}");

    let (mut j, bin) = doc(&TRI, None);
    j["accessors"][0]["count"] = json!("three");
    let p = write_embedded("types.gltf", j, &bin);
    let e = err_of(&p);
    let text = std::fs::read_to_string(&p).unwrap();
    let line = text.lines().position(|l| l.contains("\"three\"")).unwrap() + 1;
    assert!(e.starts_with(&format!("{}:{line}:", p.display())), "{e}");

    let p = tmp("v1.gltf");
    std::fs::write(&p, r#"{"asset": {"version": "1.0"}, "meshes": {}}"#).unwrap();
    assert!(err_of(&p).contains("version 1.0"));
    let p = tmp("notgltf.gltf");
    std::fs::write(&p, r#"{"position": [0, 0, 0]}"#).unwrap();
    assert!(err_of(&p).contains("not a glTF"));
}

#[test]
fn bad_references_and_data_are_errors_not_panics() {
    let check = |name: &str, edit: &dyn Fn(&mut Value), want: &str| {
        let (mut j, bin) = doc(&TRI, Some(&[0, 1, 2]));
        edit(&mut j);
        let e = err_of(&write_embedded(name, j, &bin));
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    };
    check("posidx.gltf", &|j| j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99), "out of range");
    check("nopos.gltf", &|j| j["meshes"][0]["primitives"][0]["attributes"] = json!({}), "POSITION");
    check("meshidx.gltf", &|j| j["nodes"][0]["mesh"] = json!(7), "out of range");
    check("matidx.gltf", &|j| j["meshes"][0]["primitives"][0]["material"] = json!(7), "out of range");
    check("nodeidx.gltf", &|j| j["scenes"][0]["nodes"] = json!([3]), "out of range");
    check("sceneidx.gltf", &|j| j["scene"] = json!(4), "out of range");
    check("cycle.gltf", &|j| j["nodes"][0]["children"] = json!([0]), "tree");
    check("viewidx.gltf", &|j| j["accessors"][0]["bufferView"] = json!(9), "bufferView 9");
    check("count.gltf", &|j| j["accessors"][0]["count"] = json!(1_000_000_000_000u64), "do not fit");
    check("offset.gltf", &|j| j["bufferViews"][0]["byteOffset"] = json!(1u64 << 62), "outside buffer");
    check("stride.gltf", &|j| j["bufferViews"][0]["byteStride"] = json!(4), "byteStride");
    check("vec2.gltf", &|j| j["accessors"][0]["type"] = json!("VEC2"), "expected Vec3");
    check("floatidx.gltf", &|j| j["accessors"][1]["componentType"] = json!(5126), "unsigned integer");
    check("buflen.gltf", &|j| j["buffers"][0]["byteLength"] = json!(100000), "byteLength");
    check("badb64.gltf", &|j| j["buffers"][0]["uri"] = json!("data:application/octet-stream;base64,@@@"), "base64");
    check("nob64.gltf", &|j| j["buffers"][0]["uri"] = json!("data:text/plain,hello"), "base64");
    check("url.gltf", &|j| j["buffers"][0]["uri"] = json!("https://example.com/b.bin"), "not fetched");
    check("missing.gltf", &|j| j["buffers"][0]["uri"] = json!("nowhere.bin"), "nowhere.bin");
    check("draco.gltf", &|j| j["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]), "not supported");
    check("quat.gltf", &|j| j["nodes"][0]["rotation"] = json!([0, 0, 0, 0]), "quaternion");
    check("mode.gltf", &|j| j["meshes"][0]["primitives"][0]["mode"] = json!(9), "invalid mode");
}

#[test]
fn out_of_range_vertex_index_names_the_accessor_line() {
    let (j, bin) = doc(&TRI, Some(&[0, 1, 7]));
    let p = write_embedded("vidx.gltf", j, &bin);
    let e = err_of(&p);
    assert!(e.contains("vertex index 7 is out of range"), "{e}");
    let text = std::fs::read_to_string(&p).unwrap();
    let prefix = format!("{}:", p.display());
    let l: usize = e[prefix.len()..].split(':').next().unwrap().parse().unwrap();
    let acc = text.lines().position(|l| l.contains("\"accessors\"")).unwrap() + 1;
    assert!(l > acc, "line {l} should be inside the accessors array (from {acc})");
}

#[test]
fn non_finite_positions_name_mesh_and_accessor() {
    let (j, bin) = doc(&[[0., 0., 0.], [f32::NAN, 0., 0.], [0., 1., 0.]], None);
    let e = err_of(&write_embedded("nan.gltf", j.clone(), &bin));
    assert!(e.contains("nan.gltf:") && e.contains("mesh 'm'") && e.contains("POSITION accessor 0"), "{e}");
    let e = err_of(&write_glb("nan.glb", &j, &bin));
    assert!(e.starts_with(&format!("{}: ", tmp("nan.glb").display())) && e.contains("mesh 'm'"), "{e}");
    let (mut j, bin) = doc(&TRI, None);
    j["nodes"][0]["scale"] = json!([1e39, 1, 1]);
    let e = err_of(&write_embedded("infscale.gltf", j, &bin));
    assert!(e.contains("non-finite"), "{e}");
}

#[test]
fn degenerate_triangles_are_skipped_with_a_warning() {
    let pts: [[f32; 3]; 6] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 0.], [1., 0., 0.], [2., 0., 0.]];
    let (j, bin) = doc(&pts, None);
    let p = write_embedded("degenerate.gltf", j, &bin);
    let s = Scene::from_desc(load(&p).unwrap()).unwrap();
    assert_eq!(s.polygons.len(), 1);
    assert!(s.warnings.iter().any(|w| w.to_string().contains("degenerate.gltf:")), "{:?}", s.warnings);
}
