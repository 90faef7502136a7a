//! `radiosity bake`'s GLB (`output::gltf`): what a viewer reads back must be the solution.
//!
//! - The furnace box baked: every vertex colour is k·B/π with B = E/(1 − ρ), the closed form.
//! - The Cornell box baked and read back by our own glTF reader: the same triangles, area,
//!   object names and camera; every vertex colour is the reconstructed radiance × exposure,
//!   clipped to 1, and the clipped count is what the statistics say.

use std::f64::consts::PI;

use glam::DVec3;
use radiosity::output::gltf::{auto_exposure, vertex_colors_glb, Options};
use radiosity::pipeline::{solve_scene, Settings, Solved};
use radiosity::scene::{builtin, gltf::parse_gltf, Scene};
use radiosity::NoProgress;
use serde_json::Value;

/// The JSON and BIN chunks of a GLB.
fn chunks(glb: &[u8]) -> (Value, Vec<u8>) {
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(u32::from_le_bytes(glb[4..8].try_into().unwrap()), 2);
    assert_eq!(u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize, glb.len());
    let jl = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    assert_eq!(&glb[16..20], b"JSON");
    let json: Value = serde_json::from_slice(&glb[20..20 + jl]).unwrap();
    let b0 = 20 + jl;
    let bl = u32::from_le_bytes(glb[b0..b0 + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[b0 + 4..b0 + 8], b"BIN\0");
    (json, glb[b0 + 8..b0 + 8 + bl].to_vec())
}

/// Every COLOR_0 value of every primitive (f32 VEC3).
fn colors(json: &Value, bin: &[u8]) -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    for m in json["meshes"].as_array().unwrap() {
        for p in m["primitives"].as_array().unwrap() {
            let a = &json["accessors"][p["attributes"]["COLOR_0"].as_u64().unwrap() as usize];
            assert_eq!((a["componentType"].as_u64(), a["type"].as_str()), (Some(5126), Some("VEC3")));
            let v = &json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
            let off = v["byteOffset"].as_u64().unwrap_or(0) as usize;
            for k in 0..a["count"].as_u64().unwrap() as usize {
                let f = |c: usize| f32::from_le_bytes(bin[off + 12 * k + 4 * c..off + 12 * k + 4 * c + 4].try_into().unwrap());
                out.push([f(0), f(1), f(2)]);
            }
        }
    }
    out
}

fn bake(solved: &Solved, exposure: f64) -> (Vec<u8>, radiosity::output::gltf::Stats) {
    let opts = Options { exposure, camera: solved.scene.camera, generator: "test".into() };
    vertex_colors_glb(&solved.scene, &solved.mesh, &solved.vertex_radiosity, &opts).unwrap()
}

#[test]
fn baked_furnace_vertex_colours_are_e_over_one_minus_rho() {
    let scene = Scene::from_desc(builtin::furnace(0.5, 1.0)).unwrap();
    let s = Settings { mesh_size: Some(0.25), solver: radiosity::solve::Solver::Direct, ..Default::default() };
    let solved = solve_scene(scene, &s, &NoProgress).unwrap();
    // B = πL/(1 − ρ) = 2π: radiance 2; exposure 0.3 puts it at 0.6.
    let (glb, stats) = bake(&solved, 0.3);
    let (json, bin) = chunks(&glb);
    let c = colors(&json, &bin);
    assert_eq!(c.len(), stats.vertices);
    assert!(c.len() >= 6 * 25, "{} vertices", c.len());
    for v in &c {
        for x in v {
            assert!((f64::from(*x) - 0.6).abs() < 1e-6, "vertex colour {x} against 0.6");
        }
    }
    assert_eq!(stats.clipped, 0);
    // The automatic exposure puts the furnace's one radiance at 0.8.
    let k = auto_exposure(&solved.scene, &solved.mesh, &solved.solution.display_radiosity());
    assert!((k * 2.0 - 0.8).abs() < 1e-7, "auto exposure {k}");
    let m = &json["materials"][0];
    assert_eq!(m["extensions"]["KHR_materials_unlit"], serde_json::json!({}));
    assert_eq!(m["extras"]["radiosity"]["reflectance"], serde_json::json!([0.5, 0.5, 0.5]));
    assert_eq!(json["asset"]["extras"]["radiosity"]["exposure"], serde_json::json!(0.3));
}

/// A saturated surface keeps its shading: the automatic exposure puts the brightest
/// channel, not the luminance, at 0.8, so no vertex channel is clipped (by luminance a red
/// furnace's red channel went to 2.1 at every vertex; 2026-12-06 sweep, a red glTF box
/// under a sky baked flat red).
#[test]
fn baked_red_furnace_keeps_every_channel_below_one() {
    let mut desc = builtin::furnace(0.5, 1.0);
    desc.materials[0].reflectance = radiosity::Rgb::new(0.8, 0.1, 0.1);
    let scene = Scene::from_desc(desc).unwrap();
    let s = Settings { mesh_size: Some(0.25), solver: radiosity::solve::Solver::Direct, ..Default::default() };
    let solved = solve_scene(scene, &s, &NoProgress).unwrap();
    // L = L_e/(1 − ρ) per channel: red 5, green and blue 1/0.9.
    let k = auto_exposure(&solved.scene, &solved.mesh, &solved.solution.display_radiosity());
    assert!((k * 5.0 - 0.8).abs() < 1e-6, "auto exposure {k}");
    let (glb, stats) = bake(&solved, k);
    assert_eq!(stats.clipped, 0);
    let (json, bin) = chunks(&glb);
    for v in colors(&json, &bin) {
        assert!((f64::from(v[0]) - 0.8).abs() < 1e-5 && (f64::from(v[1]) - 0.8 / 4.5).abs() < 1e-5, "{v:?}");
    }
}

#[test]
fn baked_cornell_box_reads_back_as_the_same_scene_and_light() {
    let scene = Scene::from_desc(builtin::by_name("cornell").unwrap()).unwrap();
    let solved = solve_scene(scene, &Settings::default(), &NoProgress).unwrap();
    let k = auto_exposure(&solved.scene, &solved.mesh, &solved.solution.display_radiosity());
    let (glb, stats) = bake(&solved, k);
    // Our own reader: same triangles, area and object names.
    let back = parse_gltf(&glb, std::path::Path::new("baked.glb"), |_: &str| -> std::io::Result<Vec<u8>> { unreachable!() }).unwrap();
    assert_eq!(back.polygons.len(), stats.triangles);
    let area = |v: &[DVec3]| 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
    let a_back: f64 = back.polygons.iter().map(|p| area(&p.vertices)).sum();
    let a_scene = solved.scene.total_area();
    assert!((a_back - a_scene).abs() < 1e-5 * a_scene, "area {a_back} against {a_scene}");
    let mut names: Vec<&str> = back.objects.iter().map(|o| o.name.as_str()).collect();
    let mut want: Vec<&str> = solved.scene.objects.iter().map(|o| o.name.as_str()).collect();
    names.sort_unstable();
    want.sort_unstable();
    assert_eq!(names, want);
    // The camera: position, view direction, up and field of view.
    let (c, w) = (back.camera.unwrap(), solved.scene.camera.unwrap());
    assert!((c.position - w.position).length() < 1e-3, "{c:?} against {w:?}");
    let dir = |c: &radiosity::scene::Camera| (c.look_at - c.position).normalize();
    assert!((dir(&c) - dir(&w)).length() < 1e-6 && (c.up.normalize() - w.up.normalize()).length() < 1e-6);
    assert!((c.vfov_deg - w.vfov_deg).abs() < 1e-4);
    // Colours: the vertex radiance × k, clipped, in the order written.
    let (json, bin) = chunks(&glb);
    let c = colors(&json, &bin);
    let mut expect: Vec<f32> = solved.vertex_radiosity.iter().flat_map(|b| (*b * (k / PI)).to_array()).map(|x| x.min(1.0) as f32).collect();
    let mut got: Vec<f32> = c.iter().flatten().copied().collect();
    expect.sort_by(f32::total_cmp);
    got.sort_by(f32::total_cmp);
    // Every mesh vertex is used by some element, so the multisets agree.
    assert_eq!(got.len(), expect.len());
    assert!(got.iter().zip(&expect).all(|(a, b)| (a - b).abs() <= 1e-6 * b.max(1e-3)));
    let clipped = solved.vertex_radiosity.iter().flat_map(|b| (*b * (k / PI)).to_array()).filter(|x| *x > 1.0).count();
    assert_eq!(stats.clipped, clipped);
    // The automatic exposure clips little but the light and its neighbourhood.
    assert!(clipped < got.len() / 20, "{clipped} of {} clipped", got.len());
}

/// The Cornell box's atlas: every polygon mapped without distortion at one texel size
/// (density uniform to 1e-9), every chart's polygons at least `padding` texels inside its
/// rectangle, rectangles disjoint inside the texture, and most of the texture used.
#[test]
fn cornell_atlas_is_isometric_padded_disjoint_and_well_used() {
    use radiosity::mesh::atlas::{Atlas, Options as AtlasOptions};
    let scene = Scene::from_desc(builtin::by_name("cornell").unwrap()).unwrap();
    let atlas = Atlas::build(&scene, &AtlasOptions { size: 512, ..Default::default() }).unwrap();
    assert!(atlas.padding >= 2);
    for (i, p) in scene.polygons.iter().enumerate() {
        let t: Vec<(f64, f64)> = p.vertices.iter().map(|&x| atlas.texel_coords(i as u32, x)).collect();
        for a in 0..t.len() {
            for b in a + 1..t.len() {
                let d_tex = ((t[a].0 - t[b].0).powi(2) + (t[a].1 - t[b].1).powi(2)).sqrt();
                let d_world = (p.vertices[a] - p.vertices[b]).length() / atlas.texel;
                assert!((d_tex - d_world).abs() < 1e-9 * d_world, "polygon {i}: {d_tex} texels for {d_world}");
            }
        }
        let c = &atlas.charts[atlas.chart_of[i] as usize];
        let pad = atlas.padding as f64 - 1e-9;
        for &(x, y) in &t {
            assert!(x >= c.x as f64 + pad && x <= (c.x + c.width) as f64 - pad, "polygon {i}: x {x} in chart {c:?}");
            assert!(y >= c.y as f64 + pad && y <= (c.y + c.height) as f64 - pad, "polygon {i}: y {y} in chart {c:?}");
        }
    }
    let mut owner = vec![u32::MAX; 512 * 512];
    for (k, c) in atlas.charts.iter().enumerate() {
        assert!(c.x + c.width <= 512 && c.y + c.height <= 512);
        for y in c.y..c.y + c.height {
            for x in c.x..c.x + c.width {
                assert_eq!(owner[y * 512 + x], u32::MAX, "charts {k} and {} overlap", owner[y * 512 + x]);
                owner[y * 512 + x] = k as u32;
            }
        }
    }
    let (used, covered) = (atlas.used(), atlas.covered(&scene));
    eprintln!("Cornell atlas 512²: {} charts, {:.1} % in charts, {:.1} % covered", atlas.charts.len(), 100.0 * used, 100.0 * covered);
    assert!(covered >= 0.6, "used {used}, covered {covered}");
    assert_no_overlap(&scene, &atlas);
}

/// No texel centre lies inside two polygons of the atlas (unfolded charts must not fold
/// onto themselves).
fn assert_no_overlap(scene: &Scene, atlas: &radiosity::mesh::atlas::Atlas) {
    let n = atlas.size;
    let mut owner = vec![u32::MAX; n * n];
    let mut twice = 0;
    for (i, p) in scene.polygons.iter().enumerate() {
        let t: Vec<(f64, f64)> = p.vertices.iter().map(|&x| atlas.texel_coords(i as u32, x)).collect();
        let (x0, x1) = t.iter().fold((f64::MAX, f64::MIN), |(l, h), q| (l.min(q.0), h.max(q.0)));
        let (y0, y1) = t.iter().fold((f64::MAX, f64::MIN), |(l, h), q| (l.min(q.1), h.max(q.1)));
        let area: f64 = (0..t.len()).map(|k| t[k].0 * t[(k + 1) % t.len()].1 - t[(k + 1) % t.len()].0 * t[k].1).sum();
        for y in (y0.floor().max(0.0) as usize)..(y1.ceil() as usize).min(n) {
            for x in (x0.floor().max(0.0) as usize)..(x1.ceil() as usize).min(n) {
                let c = (x as f64 + 0.5, y as f64 + 0.5);
                // Strictly inside (a centre on a shared edge belongs to neither test).
                let inside = (0..t.len()).all(|k| {
                    let (a, b) = (t[k], t[(k + 1) % t.len()]);
                    ((b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)) * area.signum() > 1e-9
                });
                if inside {
                    if owner[y * n + x] != u32::MAX {
                        twice += 1;
                    }
                    owner[y * n + x] = i as u32;
                }
            }
        }
    }
    assert_eq!(twice, 0, "{twice} texel centres lie inside two polygons");
}

/// The RenderPark classroom (reads ../shared; skips without): its surfaces cover at least
/// 60 % of a default 1024² lightmap (charts grown across bends, packed to 95 %), without
/// a texel inside two polygons.
#[test]
fn classroom_atlas_covers_sixty_percent() {
    use radiosity::mesh::atlas::{Atlas, Options as AtlasOptions};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/renderpark-classroom/classroom.obj");
    if !path.exists() {
        eprintln!("skipped: {} not found (../shared is not beside the clone)", path.display());
        return;
    }
    let scene = radiosity::scene::load_scene(path.to_str().unwrap()).unwrap();
    let atlas = Atlas::build(&scene, &AtlasOptions::default()).unwrap();
    let (used, covered) = (atlas.used(), atlas.covered(&scene));
    eprintln!("classroom atlas 1024²: {} charts, {:.1} % in charts, {:.1} % covered", atlas.charts.len(), 100.0 * used, 100.0 * covered);
    assert!(covered >= 0.6, "covered {covered}");
    assert_no_overlap(&scene, &atlas);
}

/// A lightmap of the furnace box: every texel of every chart, padding included, holds the
/// closed form L = L_e/(1 − ρ) = 2 (no unfilled, no black texel), gathered or dilated.
#[test]
fn furnace_lightmap_texels_are_all_the_closed_form() {
    use radiosity::mesh::atlas::{Atlas, Options as AtlasOptions};
    use radiosity::render::{gather, lightmap};
    let scene = Scene::from_desc(builtin::furnace(0.5, 1.0)).unwrap();
    let s = Settings { mesh_size: Some(0.25), solver: radiosity::solve::Solver::Direct, ..Default::default() };
    let solved = solve_scene(scene, &s, &NoProgress).unwrap();
    let atlas = Atlas::build(&solved.scene, &AtlasOptions { size: 64, ..Default::default() }).unwrap();
    let indirect = solved.indirect(false);
    let opts = gather::Options { width: 64, height: 64, spp_axis: 1, shadow_axis: 2, gather_axis: 0, seed: 1, noise: 0.0 };
    let l: Vec<_> = solved.solution.display_radiosity().iter().map(|b| *b / PI).collect();
    let (img, st) = lightmap::render(&solved.scene, &solved.mesh, &solved.rays, &indirect, &atlas, &l, lightmap::Quantity::Radiance, &opts, &NoProgress);
    assert!(st.shaded > 1000 && st.dilated > 0, "{st:?}");
    let mut n = 0;
    for c in &atlas.charts {
        for y in c.y..c.y + c.height {
            for x in c.x..c.x + c.width {
                let v = img.pixels[y * 64 + x];
                assert!((v.x - 2.0).abs() < 2e-3 && (v.z - 2.0).abs() < 2e-3, "texel ({x}, {y}): {v}");
                n += 1;
            }
        }
    }
    assert_eq!(n, st.shaded + st.dilated + st.flat);
}

/// Diagnostic (ignored): the atlas of any scene, `SCENE=path SIZE=2048 cargo test --release
/// -p radiosity --test bake atlas_of_a_scene -- --ignored --nocapture`.
#[test]
#[ignore]
fn atlas_of_a_scene() {
    use radiosity::mesh::atlas::{Atlas, Options as AtlasOptions};
    let Ok(path) = std::env::var("SCENE") else {
        eprintln!("set SCENE");
        return;
    };
    let size: usize = std::env::var("SIZE").ok().and_then(|s| s.parse().ok()).unwrap_or(1024);
    let mut desc = radiosity::scene::load(&path).unwrap();
    desc.two_sided = std::env::var("TWO_SIDED").is_ok();
    let scene = Scene::from_desc(desc).unwrap();
    let t = std::time::Instant::now();
    match Atlas::build(&scene, &AtlasOptions { size, ..Default::default() }) {
        Ok(atlas) => eprintln!(
            "{path} {size}²: {} polygons, {} charts, {:.1} % in charts, {:.1} % covered, {:.2} s",
            scene.polygons.len(),
            atlas.charts.len(),
            100.0 * atlas.used(),
            100.0 * atlas.covered(&scene),
            t.elapsed().as_secs_f64()
        ),
        Err(e) => eprintln!("{path} {size}²: {e} ({:.2} s)", t.elapsed().as_secs_f64()),
    }
}
