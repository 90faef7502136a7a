//! The Cornell box against the path-traced reference (Mitsuba 3, 4 M paths per face):
//! per-object area-averaged radiance.

mod common;

use radiosity::pipeline::{solve_scene, Settings};
use radiosity::scene::{builtin, Scene};
use radiosity::NoProgress;

fn reference() -> Vec<(String, [f64; 3])> {
    let text = include_str!("data/mitsuba_face_radiance.json");
    let j: serde_json::Value = serde_json::from_str(text).unwrap();
    j["faces"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let l: Vec<f64> = f["L_out_rgb"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            (f["face"].as_str().unwrap().to_string(), [l[0], l[1], l[2]])
        })
        .collect()
}

/// max over channels |L − L_ref| / max channel of L_ref (the definition).
fn rel_error(l: [f64; 3], r: [f64; 3]) -> f64 {
    let m = r.iter().cloned().fold(0.0, f64::max);
    (0..3).map(|c| (l[c] - r[c]).abs()).fold(0.0, f64::max) / m
}

/// Solves the Cornell box and returns the worst per-object error and its object.
fn worst_error(settings: &Settings) -> (f64, String, usize) {
    let scene = Scene::from_desc(builtin::cornell()).unwrap();
    let solved = solve_scene(scene, settings, &NoProgress).unwrap();
    let objects = solved.objects();
    let reference = reference();
    assert_eq!(objects.len(), 19);
    let mut worst = (0.0, String::new());
    for (name, r) in &reference {
        let o = objects.iter().find(|o| &o.name == name).unwrap_or_else(|| panic!("object {name} missing"));
        let e = rel_error(o.radiance_rgb, *r);
        if e > worst.0 {
            worst = (e, name.clone());
        }
    }
    (worst.0, worst.1, solved.mesh.len())
}

#[test]
fn cornell_box_per_object_radiance_matches_path_tracer() {
    let mut settings = Settings::default();
    settings.solve.tolerance = 1e-6;
    let (e, name, _) = worst_error(&settings);
    eprintln!("worst per-object error {:.3} % ({name})", e * 100.0);
    assert!(e <= 0.01, "worst per-object error {:.3} % ({name})", e * 100.0);
}

#[test]
fn cornell_box_per_object_radiance_with_adaptive_mesh() {
    let mut settings = Settings { adaptive: Some(Default::default()), ..Default::default() };
    settings.solve.tolerance = 1e-6;
    let (e, name, n) = worst_error(&settings);
    eprintln!("adaptive: {n} elements, worst per-object error {:.3} % ({name})", e * 100.0);
    assert!(e <= 0.01, "worst per-object error {:.3} % ({name})", e * 100.0);
}

/// The whole image against the path-traced reference (read from ../shared by path; skipped
/// without it): light-masked relative RMSE at 256², default settings, final gather.
#[test]
fn cornell_box_image_matches_path_tracer() {
    let Some(ref_path) = common::shared("reference/cornell-box/mitsuba_256x256_16384spp.exr") else { return };
    let reference = radiosity::output::exr::read(&ref_path).unwrap();
    let scene = Scene::from_desc(builtin::cornell()).unwrap();
    let camera = scene.camera.unwrap();
    let solved = solve_scene(scene, &Settings::default(), &NoProgress).unwrap();
    let two_sided: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
    let tracer = radiosity::render::gouraud::ElementTracer::new(&solved.mesh, &two_sided);
    // The default on rows: indirect light interpolated from the vertices.
    let axis = solved.default_gather_axis();
    assert_eq!(axis, 0, "rows interpolate the indirect light by default");
    let indirect = solved.indirect(false);
    let opts =
        radiosity::render::gather::Options { width: 256, height: 256, spp_axis: 6, shadow_axis: 2, gather_axis: 0, seed: 0, noise: 0.0 };
    let (img, all) = solved.render_gather(&camera, &opts, &tracer, &indirect, &NoProgress);
    let all_rays = all.rays;
    let e = radiosity::output::metrics::relative_rmse_light_masked(&img, &reference).unwrap();
    eprintln!("light-masked relative RMSE {:.3} %", e * 100.0);
    // Measured 1.63 % (the reference's own noise is 0.85 %); PRODUCT.md and BENCHMARKS.md
    // state ≤ 2 %.
    assert!(e <= 0.02, "light-masked relative RMSE {:.3} %", e * 100.0);
    // Adaptive sampling (the CLI's default): the same bound with fewer rays; most of the box
    // is smooth, only edges and penumbrae take all 36 positions. Measured 1.64 % with 44 %
    // of the rays (3.76 M against 8.58 M).
    let adaptive = radiosity::render::gather::Options { noise: radiosity::render::gather::DEFAULT_NOISE, ..opts };
    let (img, sampled) = solved.render_gather(&camera, &adaptive, &tracer, &indirect, &NoProgress);
    let rays = sampled.rays;
    let e = radiosity::output::metrics::relative_rmse_light_masked(&img, &reference).unwrap();
    eprintln!("adaptive: light-masked relative RMSE {:.3} %, {rays} rays against {all_rays}", e * 100.0);
    assert!(e <= 0.02, "adaptive: light-masked relative RMSE {:.3} %", e * 100.0);
    assert!(rays * 10 < all_rays * 9, "adaptive sampling cast {rays} rays, fixed {all_rays}");
    // Gathered indirect light (rays from every visible point reading B − E): unbiased, so
    // with enough rays (4 × 4 per position, 576 per pixel) it meets the same bound.
    // Measured 1.89 %; with 2 × 2 rays (the hierarchy's default) noise gives 3.8 %.
    let indirect = solved.indirect(true);
    let opts = radiosity::render::gather::Options { gather_axis: 4, ..opts };
    let (img, _) = solved.render_gather(&camera, &opts, &tracer, &indirect, &NoProgress);
    let e = radiosity::output::metrics::relative_rmse_light_masked(&img, &reference).unwrap();
    eprintln!("gathered 4×4: light-masked relative RMSE {:.3} %", e * 100.0);
    assert!(e <= 0.02, "gathered light-masked relative RMSE {:.3} %", e * 100.0);
    // Gouraud, the preview, is coarser but must stay well within the issue-2 bound.
    let opts = radiosity::render::gouraud::Options {
        width: 256,
        height: 256,
        spp_axis: 4,
        shading: radiosity::render::gouraud::Shading::Gouraud,
    };
    let img = solved.render(&camera, &opts, &tracer, &NoProgress);
    let e = radiosity::output::metrics::relative_rmse_light_masked(&img, &reference).unwrap();
    eprintln!("gouraud: light-masked relative RMSE {:.3} %", e * 100.0);
    assert!(e <= 0.06, "gouraud light-masked relative RMSE {:.3} %", e * 100.0);
}
