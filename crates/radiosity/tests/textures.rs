//! Textures in (glTF `baseColorTexture`/`emissiveTexture`, KHR_texture_transform, samplers;
//! OBJ/MTL `map_Kd` with `vt`): numbers that could fail.
//!
//! - Colour bleeding follows the texture's mean: a room with a checkerboard floor and a
//!   red/white striped wall solves, per object, within 1 % of the same room with each texture
//!   replaced by its mean colour (the per-element reflectance is the texture integrated over
//!   the element, so energy is right).
//! - The detail survives in images: a textured floor alone under a uniform sky receives
//!   π·L everywhere, so each gathered pixel must show ρ(texel)·L, read through the right
//!   UV orientation and sRGB decoding; elements hold the exact footprint means.
//! - OBJ `vt` runs up the image (flipped), MTL `-s`/`-o` options and `map_Ke` emission.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{DVec2, DVec3};
use radiosity::pipeline::{solve_scene, Settings, Solved};
use radiosity::render::gather;
use radiosity::render::gouraud::ElementTracer;
use radiosity::render::PinholeCamera;
use radiosity::scene::{self, Camera, Scene, Sky};
use radiosity::{NoProgress, Rgb};
use serde_json::{json, Value};

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("texture-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn srgb_to_linear(c: u8) -> f64 {
    let c = c as f64 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// An 8-bit RGB image as PNG bytes.
fn png(w: usize, h: usize, px: impl Fn(usize, usize) -> [u8; 3]) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().unwrap();
        let mut data: Vec<u8> = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                data.extend(px(x, y));
            }
        }
        wr.write_image_data(&data).unwrap();
    }
    out
}

/// Linear mean of an image's texels.
fn linear_mean(w: usize, h: usize, px: impl Fn(usize, usize) -> [u8; 3]) -> Rgb {
    let mut s = Rgb::ZERO;
    for y in 0..h {
        for x in 0..w {
            let p = px(x, y);
            s += Rgb::new(srgb_to_linear(p[0]), srgb_to_linear(p[1]), srgb_to_linear(p[2]));
        }
    }
    s / (w * h) as f64
}

/// Checkerboard of 8 × 8 texel squares (64 × 64): sRGB 235 and 40.
fn checker(x: usize, y: usize) -> [u8; 3] {
    if (x / 8 + y / 8) % 2 == 0 {
        [235; 3]
    } else {
        [40; 3]
    }
}

/// Vertical stripes 2 texels wide (64 × 64, 32 stripes across the 2-unit wall): red and
/// white. (Stripes 8 texels wide put a red stripe 0.25 from the left wall and a white one
/// at the right: real near-field bleeding then moves those walls by 0.8–0.97 % from the
/// mean-colour room; at 2 texels the largest difference is 0.23 %.)
fn stripes(x: usize, _y: usize) -> [u8; 3] {
    if (x / 2) % 2 == 0 {
        [200, 20, 20]
    } else {
        [240, 240, 240]
    }
}

fn data_uri(bytes: &[u8]) -> String {
    format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(bytes))
}

/// A glTF document of quads. Each quad: name, 4 corners (counter-clockwise seen from its
/// front), material, and optional UVs per corner.
struct Doc {
    bin: Vec<u8>,
    accessors: Vec<Value>,
    views: Vec<Value>,
    meshes: Vec<Value>,
    nodes: Vec<Value>,
}

impl Doc {
    fn new() -> Self {
        Doc { bin: Vec::new(), accessors: Vec::new(), views: Vec::new(), meshes: Vec::new(), nodes: Vec::new() }
    }

    fn push_f32(&mut self, data: &[f32], ty: &str, count: usize) -> usize {
        let off = self.bin.len();
        self.bin.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        self.views.push(json!({"buffer": 0, "byteOffset": off, "byteLength": data.len() * 4}));
        let mut acc = json!({"bufferView": self.views.len() - 1, "componentType": 5126, "count": count, "type": ty});
        if ty == "VEC3" {
            let mut lo = [f32::MAX; 3];
            let mut hi = [f32::MIN; 3];
            for c in data.chunks(3) {
                for k in 0..3 {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    fn quad(&mut self, name: &str, corners: [DVec3; 4], material: usize, uv: Option<[DVec2; 4]>) {
        let pos: Vec<f32> = corners.iter().flat_map(|c| [c.x as f32, c.y as f32, c.z as f32]).collect();
        let pa = self.push_f32(&pos, "VEC3", 4);
        let idx: Vec<u8> = [0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()).collect();
        let off = self.bin.len();
        self.bin.extend(idx);
        self.bin.extend([0u8; 4]);
        self.views.push(json!({"buffer": 0, "byteOffset": off, "byteLength": 12}));
        self.accessors
            .push(json!({"bufferView": self.views.len() - 1, "componentType": 5123, "count": 6, "type": "SCALAR"}));
        let ia = self.accessors.len() - 1;
        let mut attrs = json!({"POSITION": pa});
        if let Some(uv) = uv {
            let t: Vec<f32> = uv.iter().flat_map(|c| [c.x as f32, c.y as f32]).collect();
            attrs["TEXCOORD_0"] = json!(self.push_f32(&t, "VEC2", 4));
        }
        self.meshes
            .push(json!({"name": name, "primitives": [{"attributes": attrs, "indices": ia, "material": material}]}));
        self.nodes.push(json!({"name": name, "mesh": self.meshes.len() - 1}));
    }

    fn write(self, path: &Path, materials: Value, textures: Value, images: Value, samplers: Value) {
        let j = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": (0..self.nodes.len()).collect::<Vec<_>>()}],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "materials": materials,
            "textures": textures,
            "images": images,
            "samplers": samplers,
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [{"byteLength": self.bin.len(), "uri": data_uri_bin(&self.bin)}]
        });
        std::fs::write(path, serde_json::to_string_pretty(&j).unwrap()).unwrap();
    }
}

fn data_uri_bin(bytes: &[u8]) -> String {
    format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(bytes))
}

/// A closed 2 × 2 × 2 room (faces wound towards the inside), a ceiling light, a checkerboard floor and a
/// striped back wall (textured when `textured`, else each wall's factor is the texture's
/// linear mean). Floor UVs run 0..2 (the texture repeats twice each way).
fn room(textured: bool) -> Scene {
    let v = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let uv = |a: f64| Some([DVec2::new(0.0, 0.0), DVec2::new(0.0, a), DVec2::new(a, a), DVec2::new(a, 0.0)]);
    // Back wall UVs: stripes across x.
    let bw = [v(0., 0., 0.), v(2., 0., 0.), v(2., 2., 0.), v(0., 2., 0.)];
    let bu = [DVec2::new(0.0, 1.0), DVec2::new(1.0, 1.0), DVec2::new(1.0, 0.0), DVec2::new(0.0, 0.0)];
    let left = [v(0., 0., 0.), v(0., 2., 0.), v(0., 2., 2.), v(0., 0., 2.)];
    let right = [v(2., 0., 0.), v(2., 0., 2.), v(2., 2., 2.), v(2., 2., 0.)];
    let front = [v(0., 0., 2.), v(0., 2., 2.), v(2., 2., 2.), v(2., 0., 2.)];
    let mut d = Doc::new();
    d.quad("floor", [v(0., 0., 0.), v(0., 0., 2.), v(2., 0., 2.), v(2., 0., 0.)], 0, uv(2.0));
    d.quad("back", bw, 1, Some(bu));
    d.quad("ceiling", [v(0., 2., 0.), v(2., 2., 0.), v(2., 2., 2.), v(0., 2., 2.)], 2, None);
    d.quad("left", left, 2, None);
    d.quad("right", right, 2, None);
    d.quad("front", front, 2, None);
    d.quad("lamp", [v(0.7, 1.99, 0.7), v(1.3, 1.99, 0.7), v(1.3, 1.99, 1.3), v(0.7, 1.99, 1.3)], 3, None);
    let lamp = json!({"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
        "emissiveFactor": [1.0, 1.0, 1.0], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 10.0}}});
    let grey = json!({"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1.0]}});
    let path = tmp(if textured { "room-textured.gltf" } else { "room-mean.gltf" });
    if textured {
        let materials = json!([
            // glTF's default factor 1.0 with a texture: the texture is the colour.
            {"name": "checker", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}},
            {"name": "stripes", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}, "baseColorFactor": [1.0, 1.0, 1.0, 1.0]}},
            grey, lamp
        ]);
        let images = json!([{"uri": data_uri(&png(64, 64, checker))}, {"uri": data_uri(&png(64, 64, stripes))}]);
        let textures = json!([{"source": 0, "sampler": 0}, {"source": 1}]);
        let samplers = json!([{"wrapS": 10497, "wrapT": 10497}]);
        d.write(&path, materials, textures, images, samplers);
    } else {
        let c = linear_mean(64, 64, checker);
        let s = linear_mean(64, 64, stripes);
        let materials = json!([
            {"name": "checker", "pbrMetallicRoughness": {"baseColorFactor": [c.x, c.y, c.z, 1.0]}},
            {"name": "stripes", "pbrMetallicRoughness": {"baseColorFactor": [s.x, s.y, s.z, 1.0]}},
            grey, lamp
        ]);
        d.write(&path, materials, json!([]), json!([]), json!([]));
    }
    scene::load_scene(path.to_str().unwrap()).unwrap()
}

fn object(solved: &Solved, name: &str) -> Rgb {
    let o = solved.objects().into_iter().find(|o| o.name == name).unwrap_or_else(|| panic!("no object {name}"));
    Rgb::from_array(o.radiance_rgb)
}

#[test]
fn bleeding_follows_the_texture_mean_per_object_within_one_percent() {
    let s = Settings { mesh_size: Some(0.1), ..Default::default() };
    let tex = solve_scene(room(true), &s, &NoProgress).unwrap();
    let mean = solve_scene(room(false), &s, &NoProgress).unwrap();
    assert!(tex.scene.textures.len() == 2 && mean.scene.textures.is_empty());
    let mut worst: f64 = 0.0;
    for name in ["floor", "back", "ceiling", "left", "right", "front"] {
        let (a, b) = (object(&tex, name), object(&mean, name));
        eprintln!("{name}: textured {a} mean {b}");
        for c in 0..3 {
            let rel = (a[c] - b[c]).abs() / b[c];
            worst = worst.max(rel);
            assert!(
                rel <= 0.01,
                "{name} channel {c}: textured {} vs mean colour {} ({:.3} %)",
                a[c],
                b[c],
                100.0 * rel
            );
        }
    }
    // The red stripes must show: the ceiling is redder than it is blue.
    let ceil = object(&tex, "ceiling");
    assert!(ceil.x > 1.02 * ceil.z, "ceiling {ceil}");
    eprintln!("worst per-object difference textured vs mean colour: {:.3} %", 100.0 * worst);
}

/// A 2 × 2 textured floor alone under a uniform sky of radiance 1: every point receives π,
/// so a pixel shows ρ(x).
fn floor_under_sky(transform: Option<Value>) -> Scene {
    let v = |x: f64, z: f64| DVec3::new(x, 0.0, z);
    let mut d = Doc::new();
    let uv = [DVec2::new(0.0, 0.0), DVec2::new(0.0, 1.0), DVec2::new(1.0, 1.0), DVec2::new(1.0, 0.0)];
    d.quad("floor", [v(0., 0.), v(0., 2.), v(2., 2.), v(2., 0.)], 0, Some(uv));
    let mut info = json!({"index": 0});
    if let Some(t) = transform {
        info["extensions"] = json!({"KHR_texture_transform": t});
    }
    let materials = json!([{"name": "checker", "pbrMetallicRoughness": {"baseColorTexture": info, "baseColorFactor": [0.9, 0.9, 0.9, 1.0]}}]);
    let images = json!([{"uri": data_uri(&png(64, 64, checker))}]);
    let path = tmp("floor-sky.gltf");
    d.write(&path, materials, json!([{"source": 0, "sampler": 0}]), images, json!([{"wrapS": 33071, "wrapT": 33071}]));
    let mut desc = scene::load(path.to_str().unwrap()).unwrap();
    desc.sky = Some(Sky::uniform(Rgb::ONE));
    Scene::from_desc(desc).unwrap()
}

#[test]
fn gathered_pixels_show_each_texel_and_elements_its_footprint_mean() {
    let scene = floor_under_sky(None);
    let solved = solve_scene(scene, &Settings { mesh_size: Some(0.25), ..Default::default() }, &NoProgress).unwrap();
    // Elements: B = ρ̄·π with ρ̄ the exact mean of the checker under the element, × 0.9.
    let (dark, light) = (0.9 * srgb_to_linear(40), 0.9 * srgb_to_linear(235));
    for (i, e) in solved.mesh.elements.iter().enumerate() {
        // Floor (x, z) ∈ [0, 2]² → (u, v) = (x/2, z/2) (see the UVs above): exact mean by
        // counting the texels the element covers (it spans whole texels: 0.25 = 8 texels).
        let (c, n) = e.corners(&solved.mesh.positions);
        let lo = c[..n].iter().fold(DVec3::splat(9.0), |a, p| a.min(*p));
        let (u0, v0) = ((lo.x / 2.0 * 64.0).round() as usize, (lo.z / 2.0 * 64.0).round() as usize);
        let mut s = 0.0;
        for y in v0..v0 + 8 {
            for x in u0..u0 + 8 {
                s += if checker(x, y)[0] == 235 { light } else { dark };
            }
        }
        let want = PI * s / 64.0;
        let got = solved.solution.radiosity[i].x;
        assert!((got - want).abs() <= 1e-3 * want, "element {i} at {lo}: B {got} vs {want}");
    }
    // Pixels: a camera straight down at the floor; each pixel centre away from check borders
    // shows ρ(texel)·1.
    let cam = Camera {
        position: DVec3::new(1.0, 3.0, 1.0),
        look_at: DVec3::new(1.0, 0.0, 1.0),
        up: DVec3::X,
        vfov_deg: 36.0,
    };
    let (w, h) = (64, 64);
    let pc = PinholeCamera::new(&cam, w, h);
    let two: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
    let tracer = ElementTracer::new(&solved.mesh, &two);
    let opts = gather::Options { width: w, height: h, spp_axis: 1, shadow_axis: 1, gather_axis: 2, seed: 1, noise: 0.0 };
    let (img, _) = solved.render_gather(&cam, &opts, &tracer, &solved.indirect(false), &NoProgress);
    let mut checked = 0;
    for y in 0..h {
        for x in 0..w {
            let dir = pc.direction(x as f64 + 0.5, y as f64 + 0.5);
            let t = -pc.eye.y / dir.y;
            let p = pc.eye + dir * t;
            if !(0.0..2.0).contains(&p.x) || !(0.0..2.0).contains(&p.z) {
                continue;
            }
            let (tu, tv) = (p.x / 2.0 * 64.0, p.z / 2.0 * 64.0);
            // Skip pixels within a texel of a check border (bilinear filtering blends there).
            let near = |a: f64| {
                let m = a.rem_euclid(8.0);
                !(1.5..=6.5).contains(&m)
            };
            if near(tu) || near(tv) {
                continue;
            }
            let want = if checker(tu as usize, tv as usize)[0] == 235 { light } else { dark };
            let got = img.at(x, y).x;
            assert!((got - want).abs() <= 0.01 * want, "pixel ({x}, {y}) at {p}: {got} vs {want}");
            checked += 1;
        }
    }
    assert!(checked > 300, "only {checked} pixels checked");
}

#[test]
fn texture_transform_offsets_and_scales_lookups() {
    // scale 0.5 and offset (0.5, 0): the floor shows the texture's right half, once.
    let scene = floor_under_sky(Some(json!({"offset": [0.5, 0.0], "scale": [0.5, 0.5]})));
    let (dark, light) = (0.9 * srgb_to_linear(40), 0.9 * srgb_to_linear(235));
    for (z, x) in [(0.1, 0.1), (0.3, 0.1), (1.9, 1.9), (0.1, 0.3)] {
        // (u, v) = (x/2, z/2) → texture (0.5 + u/2, v/2) → texel (32 + 16 x, 16 z).
        let (tu, tv) = (32.0 + 16.0 * x, 16.0 * z);
        let want = if checker(tu as usize, tv as usize)[0] == 235 { light } else { dark };
        let got = scene.reflectance_at(0, DVec3::new(x, 0.0, z), 0.0).x;
        assert!((got - want).abs() < 1e-6, "at x {x} z {z}: {got} vs {want}");
    }
}

#[test]
fn obj_map_kd_reads_vt_upwards_and_map_ke_emits() {
    let dir = tmp("obj");
    std::fs::create_dir_all(&dir).unwrap();
    // Top half red, bottom half white (image rows run down).
    std::fs::write(dir.join("halves.png"), png(4, 4, |_, y| if y < 2 { [255, 0, 0] } else { [255, 255, 255] }))
        .unwrap();
    std::fs::write(dir.join("glow.png"), png(2, 2, |_, _| [128, 128, 128])).unwrap();
    std::fs::write(
        dir.join("t.mtl"),
        "newmtl tex\nKd 0.5 0.5 0.5\nmap_Kd -s 1 1 1 halves.png\nnewmtl glow\nKd 0 0 0\nKe 2 2 2\nmap_Ke glow.png\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("t.obj"),
        "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl tex\nf 1/1 2/2 3/3 4/4\nusemtl glow\nv 0 0 1\nv 1 0 1\nv 1 1 1\nf 5 6 7\n",
    )
    .unwrap();
    let scene = scene::load_scene(dir.join("t.obj").to_str().unwrap()).unwrap();
    // vt v = 0.75 is the upper half of the image in OBJ's convention: red.
    let top = scene.reflectance_at(0, DVec3::new(0.5, 0.75, 0.0), 0.0);
    let bottom = scene.reflectance_at(0, DVec3::new(0.5, 0.25, 0.0), 0.0);
    assert!((top - Rgb::new(0.5, 0.0, 0.0)).abs().max_element() < 1e-6, "top {top}");
    assert!((bottom - Rgb::splat(0.5)).abs().max_element() < 1e-6, "bottom {bottom}");
    // Mean over the whole face: half red, half white.
    let m = &scene.materials[scene.polygons[0].material as usize];
    assert!((m.reflectance - Rgb::new(0.5, 0.25, 0.25)).abs().max_element() < 1e-6, "{}", m.reflectance);
    // map_Ke: Ke × the texture (sRGB 128 → 0.2158605), without texture coordinates its mean.
    let g = srgb_to_linear(128);
    let glow = scene.polygons.iter().position(|p| scene.materials[p.material as usize].name == "glow").unwrap();
    let e = scene.emission_at(glow, DVec3::new(0.5, 0.2, 1.0), 0.0);
    assert!((e - Rgb::splat(2.0 * g)).abs().max_element() < 1e-6, "{e}");
    // Through a TOML scene file (two meshes: textures renumbered), the same lookups.
    // The second mesh: the same, 10 units along x.
    let text = std::fs::read_to_string(dir.join("t.obj")).unwrap();
    let moved = text.lines().map(|l| match l.strip_prefix("v ") {
        Some(r) => {
            let c: Vec<f64> = r.split_whitespace().map(|x| x.parse().unwrap()).collect();
            format!("v {} {} {}\n", c[0] + 10.0, c[1], c[2])
        }
        None => format!("{l}\n"),
    });
    std::fs::write(dir.join("t2.obj"), moved.collect::<String>()).unwrap();
    std::fs::write(dir.join("t.toml"), "meshes = [\"t.obj\", \"t2.obj\"]\n").unwrap();
    let via = scene::load_scene(dir.join("t.toml").to_str().unwrap()).unwrap();
    let n = scene.polygons.len();
    assert_eq!((via.textures.len(), via.polygons.len()), (2 * scene.textures.len(), 2 * n));
    for k in 0..2 * n {
        let shift = if k < n { 0.0 } else { 10.0 };
        for p in [DVec3::new(0.5, 0.75, 0.0), DVec3::new(0.5, 0.25, 0.0), DVec3::new(0.5, 0.2, 1.0)] {
            let q = p + DVec3::new(shift, 0.0, 0.0);
            let (a, b) = (via.reflectance_at(k, q, 0.0), scene.reflectance_at(k % n, p, 0.0));
            assert!((a - b).abs().max_element() < 1e-12, "polygon {k}: ρ {a} via TOML, {b} direct");
            let (a, b) = (via.emission_at(k, q, 0.0), scene.emission_at(k % n, p, 0.0));
            assert!((a - b).abs().max_element() < 1e-12, "polygon {k}: Le {a} via TOML, {b} direct");
        }
    }
}

#[test]
fn bad_textures_are_clear_errors() {
    let dir = tmp("bad");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("not.png"), b"this is not an image").unwrap();
    std::fs::write(dir.join("b.mtl"), "newmtl tex\nmap_Kd not.png\n").unwrap();
    std::fs::write(dir.join("b.obj"), "mtllib b.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl tex\nf 1 2 3\n").unwrap();
    let e = scene::load(dir.join("b.obj").to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("b.mtl:2") && e.contains("not.png"), "{e}");
    std::fs::write(dir.join("c.mtl"), "newmtl tex\nmap_Kd missing.png\n").unwrap();
    std::fs::write(dir.join("c.obj"), "mtllib c.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl tex\nf 1 2 3\n").unwrap();
    let e = scene::load(dir.join("c.obj").to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("c.mtl:2") && e.contains("missing.png"), "{e}");
    // A vt index out of range is a warning naming the line; the face is kept.
    std::fs::write(dir.join("d.obj"), "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/2 3/3\n").unwrap();
    let d = scene::load(dir.join("d.obj").to_str().unwrap()).unwrap();
    assert_eq!(d.polygons.len(), 1);
    assert!(d.polygons[0].uvs.is_empty());
    let w = d.warnings.iter().find(|w| w.msg.contains("texture index")).expect("a warning");
    assert!(w.loc.as_ref().is_some_and(|l| l.to_string().contains("d.obj:5")), "{w:?}");
}

/// Issue 11, `bake --lightmap --lightmap-mode moz`: the lightmap holds the irradiance E
/// (every floor texel: the radiance lightmap's L = Le + ρ(x)·E/π to 1e-9, ρ the checker
/// under it), the GLB keeps the checker as the floor's baseColorTexture (its sRGB bytes
/// back exactly) on TEXCOORD_0 = the file's UVs, holds no vertex colours, and its
/// MOZ_lightmap texels times the intensity give k·E to the 8-bit step.
#[test]
fn moz_lightmap_keeps_the_texture_and_holds_the_irradiance() {
    use radiosity::mesh::atlas::{Atlas, Options as AtlasOptions};
    use radiosity::output::gltf::{baked_glb, moz_lightmap_png, Lightmap, LightmapMode, Options};
    use radiosity::render::lightmap::{self, Quantity};
    let s = Settings { mesh_size: Some(0.25), ..Default::default() };
    let solved = solve_scene(room(true), &s, &NoProgress).unwrap();
    let n = 128;
    let atlas = Atlas::build(&solved.scene, &AtlasOptions { size: n, ..Default::default() }).unwrap();
    let indirect = solved.indirect(false);
    let opts = gather::Options { width: n, height: n, spp_axis: 1, shadow_axis: 2, gather_axis: 0, seed: 1, noise: 0.0 };
    let b = solved.solution.display_radiosity();
    let l: Vec<_> = b.iter().map(|b| *b / PI).collect();
    let sc = &solved.scene;
    let (rad, _) = lightmap::render(sc, &solved.mesh, &solved.rays, &indirect, &atlas, &l, Quantity::Radiance, &opts, &NoProgress);
    let (irr, st) = lightmap::render(sc, &solved.mesh, &solved.rays, &indirect, &atlas, &l, Quantity::Irradiance, &opts, &NoProgress);
    assert!(st.shaded > 1000, "{st:?}");
    // Every texel centre well inside the floor: L = ρ(x)·E/π.
    let floor = sc.polygons.iter().position(|p| sc.objects[p.object as usize].name == "floor").unwrap();
    let ch = &atlas.charts[atlas.chart_of[floor] as usize];
    let mut checked = 0;
    for y in ch.y..ch.y + ch.height {
        for x in ch.x..ch.x + ch.width {
            let p = atlas.world(floor as u32, x as f64 + 0.5, y as f64 + 0.5);
            if !(p.x > 0.02 && p.x < 1.98 && p.z > 0.02 && p.z < 1.98 && p.y.abs() < 1e-9) {
                continue;
            }
            let rho = sc.reflectance_at(floor, p, atlas.texel * atlas.texel);
            let (lt, et) = (rad.pixels[y * n + x], irr.pixels[y * n + x]);
            let want = rho * et / PI;
            assert!((lt - want).abs().max_element() <= 1e-9 * lt.max_element().max(1e-12), "texel ({x}, {y}): L {lt}, ρE/π {want}");
            checked += 1;
        }
    }
    assert!(checked > 500, "{checked} floor texels");

    let k = 0.7;
    let rho_ref = radiosity::output::gltf::moz_reference_reflectance(sc);
    let (png, intensity, clipped) = moz_lightmap_png(&irr, k, rho_ref).unwrap();
    // Clipped: at most the brightest 0.1 %, or texels that show white on a surface of the
    // reference reflectance (ρ_ref·k·E/π ≥ 1).
    let over: Vec<f64> = irr.pixels.iter().map(|p| p.max_element() * k).filter(|&e| e > intensity).collect();
    assert_eq!(over.len(), clipped);
    assert!(clipped <= n * n / 1000 + 1 || over.iter().all(|e| rho_ref * e / PI >= 1.0 - 1e-9), "{clipped} clipped");
    let vb = &solved.vertex_radiosity;
    let gopts = Options { exposure: k, camera: None, generator: "test".into() };
    let lm = Lightmap { atlas: &atlas, png: &png, mode: LightmapMode::Moz, intensity };
    let (glb, _) = baked_glb(sc, &solved.mesh, vb, Some(lm), &gopts).unwrap();
    let g = gltf::Gltf::from_slice(&glb).unwrap();
    let blob = g.blob.as_deref().unwrap();
    assert!(g.extensions_used().any(|e| e == "MOZ_lightmap"));
    let image_bytes = |img: gltf::Image| match img.source() {
        gltf::image::Source::View { view, .. } => &blob[view.offset()..view.offset() + view.length()],
        _ => panic!("image not in the buffer"),
    };
    let decode = |bytes: &[u8]| image::load_from_memory_with_format(bytes, image::ImageFormat::Png).unwrap().to_rgb8();
    let mat = g.materials().find(|m| m.name() == Some("checker")).unwrap();
    let doc: Value = serde_json::from_slice(&gltf::binary::Glb::from_slice(&glb).unwrap().json).unwrap();
    let ext = &doc["materials"][mat.index().unwrap()]["extensions"]["MOZ_lightmap"];
    assert!(ext.is_object(), "no MOZ_lightmap on the material");
    assert_eq!(ext["texCoord"], 1);
    assert!((ext["intensity"].as_f64().unwrap() - intensity).abs() <= 1e-12 * intensity);
    // The checker comes back byte for byte.
    let base = mat.pbr_metallic_roughness().base_color_texture().expect("baseColorTexture kept");
    assert_eq!(base.tex_coord(), 0);
    let tex = decode(image_bytes(base.texture().source()));
    assert_eq!(tex.dimensions(), (64, 64));
    for (x, y, p) in tex.enumerate_pixels() {
        assert_eq!(p.0, checker(x as usize, y as usize), "checker texel ({x}, {y})");
    }
    // The lightmap's texels × intensity = k·E (8-bit linear: half a step).
    let lmi = g.textures().nth(ext["index"].as_u64().unwrap() as usize).unwrap();
    let lmap = decode(image_bytes(lmi.source()));
    let step = intensity / 255.0;
    let mut worst: f64 = 0.0;
    for (x, y, p) in lmap.enumerate_pixels() {
        let e = irr.pixels[y as usize * n + x as usize] * k;
        if e.max_element() > intensity {
            continue;
        }
        for c in 0..3 {
            worst = worst.max((p.0[c] as f64 / 255.0 * intensity - e[c]).abs());
        }
    }
    assert!(worst <= 0.5 * step + 1e-9, "lightmap off by {worst:.3e}, step {step:.3e}");
    // The floor's TEXCOORD_0 = the file's UVs (u, v) = (x, z); no vertex colours anywhere.
    for mesh in g.meshes() {
        for prim in mesh.primitives() {
            assert!(prim.get(&gltf::Semantic::Colors(0)).is_none(), "COLOR_0 under MOZ_lightmap");
            if prim.material().name() != Some("checker") {
                continue;
            }
            let read = |a: gltf::Accessor| -> Vec<f32> {
                let v = a.view().unwrap();
                let o = v.offset() + a.offset();
                blob[o..o + a.count() * a.size()].chunks(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect()
            };
            let pos = read(prim.get(&gltf::Semantic::Positions).unwrap());
            let uv = read(prim.get(&gltf::Semantic::TexCoords(0)).unwrap());
            for (p, t) in pos.chunks(3).zip(uv.chunks(2)) {
                assert!((t[0] - p[0]).abs() < 1e-5 && (t[1] - p[2]).abs() < 1e-5, "vertex {p:?}: uv {t:?}");
            }
        }
    }
}

/// Issue 11, "the input scene's nodes kept": a glTF whose quads hang under a translated,
/// turned group node, one of them mirrored (scale −1), bakes back into the same node tree
/// (names, parents, transforms) with each object's mesh in its node's frame; read again,
/// every object has the same area, facing (area-weighted normal) and bounds in the scene
/// as the input's, the mirrored one included.
#[test]
fn bake_keeps_the_gltf_node_tree() {
    let v = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let mut d = Doc::new();
    d.quad("floor", [v(0., 0., 0.), v(0., 0., 2.), v(2., 0., 2.), v(2., 0., 0.)], 0, None);
    d.quad("wall", [v(0., 0., 0.), v(2., 0., 0.), v(2., 2., 0.), v(0., 2., 0.)], 0, None);
    d.quad("lamp", [v(0.7, 1.9, 0.7), v(1.3, 1.9, 0.7), v(1.3, 1.9, 1.3), v(0.7, 1.9, 1.3)], 1, None);
    let path = tmp("nodes.gltf");
    let grey = json!({"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1.0]}});
    let lamp = json!({"name": "lamp", "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]}, "emissiveFactor": [1.0, 1.0, 1.0]});
    d.write(&path, json!([grey, lamp]), json!([]), json!([]), json!([]));
    // Re-parent: group (translated, turned 90° about +Y) > floor (mirrored in x), wall, lamp.
    let mut j: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    j["nodes"][0]["scale"] = json!([-1.0, 1.0, 1.0]);
    let s = std::f64::consts::FRAC_1_SQRT_2;
    j["nodes"].as_array_mut().unwrap().push(json!({"name": "group", "translation": [3.0, 0.5, -1.0], "rotation": [0.0, s, 0.0, s], "children": [0, 1, 2]}));
    j["scenes"][0]["nodes"] = json!([3]);
    std::fs::write(&path, serde_json::to_string(&j).unwrap()).unwrap();

    let scene = scene::load_scene(path.to_str().unwrap()).unwrap();
    let solved = solve_scene(scene, &Settings { mesh_size: Some(0.5), ..Default::default() }, &NoProgress).unwrap();
    let opts = radiosity::output::gltf::Options { exposure: 1.0, camera: None, generator: "test".into() };
    let (glb, _) = radiosity::output::gltf::vertex_colors_glb(&solved.scene, &solved.mesh, &solved.vertex_radiosity, &opts).unwrap();
    let out = tmp("nodes-baked.glb");
    std::fs::write(&out, &glb).unwrap();
    // The tree: group at the root with the three objects as its children, transforms kept.
    let doc: Value = serde_json::from_slice(&gltf::binary::Glb::from_slice(&glb).unwrap().json).unwrap();
    let nodes = doc["nodes"].as_array().unwrap();
    let by_name = |n: &str| nodes.iter().position(|x| x["name"] == n).unwrap_or_else(|| panic!("no node {n}"));
    let group = by_name("group");
    let kids: Vec<u64> = nodes[group]["children"].as_array().unwrap().iter().map(|c| c.as_u64().unwrap()).collect();
    for name in ["floor", "wall", "lamp"] {
        assert!(kids.contains(&(by_name(name) as u64)), "{name} is not a child of group");
        assert!(nodes[by_name(name)]["mesh"].is_u64(), "{name} has no mesh");
    }
    assert_eq!(doc["scenes"][0]["nodes"][0], group);
    let m: Vec<f64> = nodes[by_name("floor")]["matrix"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert!((glam::DMat4::from_cols_slice(&m).determinant() + 1.0).abs() < 1e-6, "floor's mirror lost: {m:?}");
    // Read back: the same geometry in the scene, facing the same way.
    let back = scene::load_scene(out.to_str().unwrap()).unwrap();
    let summary = |s: &Scene, name: &str| {
        let o = s.objects.iter().position(|o| o.name == name).unwrap() as u32;
        let (mut area, mut n, mut lo, mut hi) = (0.0, DVec3::ZERO, DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
        for p in s.polygons.iter().filter(|p| p.object == o) {
            area += p.area;
            n += p.normal * p.area;
            for x in &p.vertices {
                lo = lo.min(*x);
                hi = hi.max(*x);
            }
        }
        (area, n / area, lo, hi)
    };
    for name in ["floor", "wall", "lamp"] {
        let (a0, n0, lo0, hi0) = summary(&solved.scene, name);
        let (a1, n1, lo1, hi1) = summary(&back, name);
        eprintln!("{name}: area {a0} -> {a1}, normal {n0} -> {n1}");
        assert!((a1 - a0).abs() < 1e-5 * a0, "{name}: area {a1} against {a0}");
        assert!((n1 - n0).length() < 1e-5, "{name}: facing {n1} against {n0}");
        assert!((lo1 - lo0).abs().max_element() < 1e-5 && (hi1 - hi0).abs().max_element() < 1e-5, "{name}: bounds moved");
    }
}

/// Under MOZ_lightmap an emission texture is kept too (MTL map_Ke on the lamp): the lamp's
/// material shows it as its emissiveTexture (the texels back byte for byte), with Ke × the
/// exposure as the factor.
#[test]
fn moz_bake_keeps_emission_textures() {
    use radiosity::mesh::atlas::{Atlas, Options as AtlasOptions};
    use radiosity::output::gltf::{baked_glb, moz_lightmap_png, Lightmap, LightmapMode, Options};
    use radiosity::render::lightmap::{self, Quantity};
    let dir = tmp("moz-emission");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("glow.png"), png(2, 2, |x, y| [100 + 50 * x as u8, 120, 140 + 20 * y as u8])).unwrap();
    std::fs::write(dir.join("e.mtl"), "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl glow\nKd 0 0 0\nKe 0.4 0.4 0.4\nmap_Ke glow.png\n").unwrap();
    std::fs::write(
        dir.join("e.obj"),
        "mtllib e.mtl\nv 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 1 1 1\nv 0 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl grey\nf 1 2 3 4\nusemtl glow\nf 5/1 6/2 7/3 8/4\n",
    )
    .unwrap();
    let scene = scene::load_scene(dir.join("e.obj").to_str().unwrap()).unwrap();
    let solved = solve_scene(scene, &Settings { mesh_size: Some(0.5), ..Default::default() }, &NoProgress).unwrap();
    let atlas = Atlas::build(&solved.scene, &AtlasOptions { size: 64, ..Default::default() }).unwrap();
    let l: Vec<_> = solved.solution.display_radiosity().iter().map(|b| *b / PI).collect();
    let gopts = gather::Options { width: 64, height: 64, spp_axis: 1, shadow_axis: 1, gather_axis: 0, seed: 1, noise: 0.0 };
    let (irr, _) = lightmap::render(&solved.scene, &solved.mesh, &solved.rays, &solved.indirect(false), &atlas, &l, Quantity::Irradiance, &gopts, &NoProgress);
    let k = 2.0;
    let (png_bytes, intensity, _) = moz_lightmap_png(&irr, k, 0.0).unwrap();
    let lm = Lightmap { atlas: &atlas, png: &png_bytes, mode: LightmapMode::Moz, intensity };
    let opts = Options { exposure: k, camera: None, generator: "test".into() };
    let (glb, _) = baked_glb(&solved.scene, &solved.mesh, &solved.vertex_radiosity, Some(lm), &opts).unwrap();
    let g = gltf::Gltf::from_slice(&glb).unwrap();
    let blob = g.blob.as_deref().unwrap();
    let glow = g.materials().find(|m| m.name() == Some("glow")).unwrap();
    let f = glow.emissive_factor();
    assert!(f.iter().all(|c| (c - 0.8).abs() < 1e-6), "emissive factor {f:?}");
    let tex = glow.emissive_texture().expect("emission texture kept");
    let gltf::image::Source::View { view, .. } = tex.texture().source().source() else { panic!("image not in the buffer") };
    let img = image::load_from_memory(&blob[view.offset()..view.offset() + view.length()]).unwrap().to_rgb8();
    for (x, y, p) in img.enumerate_pixels() {
        assert_eq!(p.0, [100 + 50 * x as u8, 120, 140 + 20 * y as u8], "glow texel ({x}, {y})");
    }
}
