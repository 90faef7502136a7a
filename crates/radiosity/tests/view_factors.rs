//! Issue 3: every form-factor method against the closed forms of
//! ../shared/reference/analytic_view_factors*.csv (copied into tests/data), the unit cube,
//! the Cornell box reference, closed rooms, View3D inputs and the enclosure correction.
//!
//! Tolerances (the "done means"): analytic ≤ 1e-9 relative; adaptive ≤ 1e-5;
//! Monte Carlo and point-sampled ≤ 0.5 % at their defaults; hemicube ≤ 2 % at its default
//! resolution (asserted at PRODUCT.md's stricter 1 %; measured worst 0.47 %). The CSV
//! prints rectangles to 9 decimals, so those cases are checked against the closed form
//! evaluated here in f64 (and the CSV against the closed form to its printed precision);
//! the disks' CSV values are exact for the disks, and a 256-gon of equal area differs
//! from its disk by up to ~4e-10 (README), well inside 1e-9 relative.
//!
//! Meshes: the element methods (hemicube, point-sampled, Monte Carlo) need the sender cut
//! into elements; rectangles use the default size (scene diagonal / 40; the hemicube, the
//! slowest, diagonal / 20), disks the 256-gon cut into 3 rings of 256 elements. The
//! area-to-area methods (analytic, adaptive) use each polygon whole.

mod vf_common;

use vf_common::{cases, Case, Kind};
use radiosity::form_factor::{Method, Options};
use radiosity::scene::Scene;
use radiosity::view_factors::{compute, Job, Per, Settings, ViewFactors};
use radiosity::{Error, NoProgress};

fn run(scene: Scene, method: Method, mesh_size: Option<f64>, tweak: impl FnOnce(&mut Options)) -> ViewFactors {
    let mut form_factors = Options { method, ..Default::default() };
    tweak(&mut form_factors);
    let settings = Settings { per: Per::Object, mesh_size, form_factors, enclosure: false };
    compute(scene, &settings, &NoProgress).unwrap()
}

/// F from "from" to "to" for a case, with the element methods' meshes described above.
fn factor(c: &Case, method: Method, tweak: impl FnOnce(&mut Options)) -> f64 {
    let (scene, size) = match (c.kind, method.is_area_to_area()) {
        (Kind::Disks { .. }, false) => (c.kind.scene_rings(3), Some(0.0)),
        (_, true) => (c.kind.scene(), None),
        (_, false) if method == Method::Hemicube => {
            let s = c.kind.scene();
            let d = s.diagonal();
            (s, Some(d / 20.0))
        }
        (_, false) => (c.kind.scene(), None),
    };
    let vf = run(scene, method, size, tweak);
    assert_eq!(vf.names, ["from", "to"]);
    vf.matrix.get(0, 1)
}

fn check_all(method: Method, tol: f64, tweak: impl Fn(&mut Options)) {
    let mut worst = (0.0f64, String::new());
    for c in cases() {
        let exact = c.kind.exact();
        let f = factor(&c, method, &tweak);
        let rel = ((f - exact) / exact).abs();
        if rel > worst.0 {
            worst = (rel, c.label.clone());
        }
        assert!(rel <= tol, "{}: {}: F = {f:.12} vs {exact:.12} (relative {rel:.2e} > {tol:.0e})", method.name(), c.label);
    }
    eprintln!("{}: worst relative error {:.2e} ({})", method.name(), worst.0, worst.1);
}

#[test]
fn reference_values_are_the_closed_forms() {
    for c in cases() {
        let exact = c.kind.exact();
        let printed = if matches!(c.kind, Kind::Disks { .. }) { 5e-13 } else { 5e-10 };
        assert!((exact - c.csv).abs() <= printed + 1e-15, "{}: closed form {exact:.12} vs CSV {}", c.label, c.csv);
    }
}

#[test]
fn analytic_every_reference_case_to_1e9() {
    check_all(Method::Analytic, 1e-9, |_| {});
    // The disks against the CSV itself (exact disk values): the 256-gon's own error
    // (~4e-10 absolute) is inside the tolerance.
    for c in cases().iter().filter(|c| matches!(c.kind, Kind::Disks { .. })) {
        let f = factor(c, Method::Analytic, |_| {});
        assert!(((f - c.csv) / c.csv).abs() <= 1e-9, "{}: {f} vs {}", c.label, c.csv);
    }
}

#[test]
fn adaptive_every_reference_case_to_1e5() {
    check_all(Method::Adaptive, 1e-5, |_| {});
    // The integration itself (not the contour integral it takes when nothing occludes).
    check_all(Method::Adaptive, 1e-5, |o| o.adaptive_always_integrate = true);
}

#[test]
fn monte_carlo_every_reference_case_to_half_a_percent() {
    check_all(Method::MonteCarlo, 5e-3, |_| {});
}

#[test]
fn point_sampled_every_reference_case_to_half_a_percent() {
    check_all(Method::PointSampled, 5e-3, |_| {});
}

/// The disks as a user gives them (one 256-gon each, default mesh): refined Delaunay
/// triangles, not a fan of k² slivers per fan triangle (~73k elements per disk before).
#[test]
fn default_meshed_disks_are_compact_and_accurate() {
    for c in cases().into_iter().filter(|c| matches!(c.kind, Kind::Disks { .. })) {
        let exact = c.kind.exact();
        for (method, tol) in [(Method::PointSampled, 5e-3), (Method::MonteCarlo, 5e-3)] {
            let vf = run(c.kind.scene(), method, None, |_| {});
            let f = vf.matrix.get(0, 1);
            let rel = ((f - exact) / exact).abs();
            assert!(rel <= tol, "{} {}: F = {f:.9} vs {exact:.9} ({rel:.2e})", method.name(), c.label);
            assert!(vf.elements < 8_000, "{}: {} elements", c.label, vf.elements);
        }
    }
}

#[test]
fn hemicube_every_reference_case_to_one_percent() {
    check_all(Method::Hemicube, 1e-2, |_| {}); // PRODUCT.md: ≤ 1 % at the default resolution
}

/// The hemicube's proximity error: an element beside a surface sees it from its centre at
/// point-blank range. Two unit squares at a right angle, one element each: one hemicube
/// gives 0.190 (−5 %); the 3 × 3 hemicubes it switches to near surfaces give 0.199. The
/// same error, summed over the housing of office2's small lamp, created energy (every
/// surface 9 % too bright; BENCHMARKS.md, "Form factors").
#[test]
fn hemicube_corrects_its_proximity_error() {
    let c = cases().into_iter().find(|c| c.label.contains("perpendicular_rect_common_edge w=1;h=1;l=1")).unwrap();
    let exact = c.kind.exact();
    let f = |k: usize| run(c.kind.scene(), Method::Hemicube, Some(2.0), |o| o.max_receiver_samples = k).matrix.get(0, 1);
    let (one, fixed) = (f(1), f(3));
    assert!(((fixed - exact) / exact).abs() <= 1e-2, "{fixed} vs {exact}");
    assert!(((one - exact) / exact).abs() > 3e-2, "the single-point error this guards against: {one} vs {exact}");
}

#[test]
fn unit_cube_rows_sum_to_one_for_every_method() {
    let (opp, adj) = (0.199824895698, 0.200043776075); // Howell C-11 / C-14 for a unit cube
    for (method, tol) in [
        (Method::Analytic, 1e-9),
        (Method::Adaptive, 1e-5),
        (Method::MonteCarlo, 5e-3),
        (Method::PointSampled, 5e-3),
        (Method::Hemicube, 1e-2),
    ] {
        let cube = vf_common::unit_cube();
        // Hemicube and Monte Carlo on a diag/20 mesh (faster); point-sampled at its default.
        let coarse = matches!(method, Method::Hemicube | Method::MonteCarlo);
        let size = if coarse { Some(cube.diagonal() / 20.0) } else { None };
        let vf = run(cube, method, size, |_| {});
        assert_eq!(vf.matrix.n(), 6);
        for i in 0..6 {
            let sum: f64 = vf.matrix.row(i).iter().sum();
            assert!((sum - 1.0).abs() <= tol, "{}: row {i} sums to {sum}", method.name());
            for j in 0..6 {
                let f = vf.matrix.get(i, j);
                let expect = if i == j {
                    0.0
                } else if (i / 2) == (j / 2) {
                    opp
                } else {
                    adj
                };
                assert!((f - expect).abs() <= tol * expect.max(1e-300) + 1e-15, "{}: F[{i}][{j}] = {f}", method.name());
            }
        }
    }
}

/// Done-means 2: the per-object Cornell box matrix with occlusion against the Monte Carlo
/// reference (4 M rays per face, standard error ≤ 2.5e-4), floor row included.
#[test]
fn cornell_adaptive_matches_the_reference_to_1e3() {
    let text = std::fs::read_to_string(format!("{}/cornell_view_factors_monte_carlo.json", vf_common::DATA)).unwrap();
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    let names: Vec<&str> = r["faces"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    let scene = Scene::from_desc(radiosity::scene::builtin::cornell()).unwrap();
    let vf = run(scene, Method::Adaptive, None, |_| {});
    assert_eq!(vf.names, names);
    let mut worst: f64 = 0.0;
    for (i, row) in r["F_i_to_j"].as_array().unwrap().iter().enumerate() {
        for (j, v) in row.as_array().unwrap().iter().enumerate() {
            let e = (vf.matrix.get(i, j) - v.as_f64().unwrap()).abs();
            assert!(e <= 1e-3, "F[{}][{}] = {} vs {}", names[i], names[j], vf.matrix.get(i, j), v);
            worst = worst.max(e);
        }
    }
    eprintln!("Cornell box, adaptive: max |ΔF| = {worst:.2e}");
    // Reciprocity holds by construction (each pair is one integral), up to the row guard,
    // which scales a row that the integration tolerance took above 1 back to 1.
    let scaled = (vf.stats.guard.max_row_sum - 1.0).max(0.0);
    assert!(scaled <= 1e-5, "raw row sum {}", vf.stats.guard.max_row_sum);
    assert!(vf.diagnostics.reciprocity_max_rel.unwrap() <= 1e-12 + scaled, "{:?} (rows scaled by up to {scaled:e})", vf.diagnostics.reciprocity_max_rel);
    assert!(vf.diagnostics.row_sum_max <= 1.0 + 1e-9);
}

/// The Cornell box closed by a front wall: every row sums to 1 except the floor's, which
/// loses exactly the two blocks' footprints (floor under a block sees only the block's
/// inside). Closure is not enforced by any method, so this checks occluded factors.
#[test]
fn closed_cornell_box_rows_close() {
    use glam::DVec3;
    let mut d = radiosity::scene::builtin::cornell();
    d.objects.push(radiosity::scene::ObjectDesc { name: "front".into(), loc: None });
    let white = d.materials.iter().position(|m| m.name == "white").unwrap() as u32;
    d.polygons.push(radiosity::scene::PolygonDesc { uvs: Vec::new(),
        vertices: vec![DVec3::new(0., 0., 0.), DVec3::new(552.8, 0., 0.), DVec3::new(556., 548.8, 0.), DVec3::new(0., 548.8, 0.)],
        material: white,
        object: d.objects.len() as u32 - 1,
        loc: None,
    });
    let scene = Scene::from_desc(d).unwrap();
    let floor_area = 308231.04;
    let footprints = 27633.0 + 27626.5; // short_top and tall_top (vertical blocks)
    let floor_sum = 1.0 - footprints / floor_area;
    for (method, tol) in [(Method::Adaptive, 1e-5), (Method::MonteCarlo, 2e-3)] {
        let size = if method == Method::MonteCarlo { Some(scene.diagonal() / 20.0) } else { None };
        let vf = run(scene.clone(), method, size, |_| {});
        for i in 0..vf.matrix.n() {
            let sum: f64 = vf.matrix.row(i).iter().sum();
            let expect = if vf.names[i] == "floor" { floor_sum } else { 1.0 };
            assert!((sum - expect).abs() <= tol, "{}: row {} sums to {sum}, expected {expect}", method.name(), vf.names[i]);
        }
    }
}

#[test]
fn enclosure_correction_makes_box345_reciprocal_and_closed() {
    let (desc, ctrl) = radiosity::scene::vs3::read_vs3(std::path::Path::new(&format!("{}/box345.vs3", vf_common::DATA))).unwrap();
    assert!(ctrl.enclosure, "box345.vs3 asks for encl=1");
    let scene = Scene::from_desc(desc).unwrap();
    let settings = Settings {
        per: Per::Object,
        mesh_size: Some(0.0),
        form_factors: Options { method: Method::MonteCarlo, ..Default::default() },
        enclosure: true,
    };
    let vf = compute(scene, &settings, &NoProgress).unwrap();
    assert_eq!(vf.matrix.n(), 106);
    let before = vf.before_enclosure.as_ref().unwrap();
    let rep = vf.enclosure.as_ref().unwrap();
    assert!(before.reciprocity_max_rel.unwrap() > 1e-3, "Monte Carlo is not reciprocal by itself");
    assert!(vf.diagnostics.reciprocity_max_rel.unwrap() <= 1e-6, "{:?}", vf.diagnostics);
    assert!(vf.diagnostics.closure_max_error <= 1e-9, "{:?}", vf.diagnostics);
    assert!(rep.max_change > 0.0 && rep.max_change < 0.05, "{rep:?}");
    assert_eq!(vf.diagnostics.negative_entries, 0);
}

#[test]
fn view3d_parallel_planes() {
    let path = format!("{}/ParallelPlanes.vs3", vf_common::DATA);
    let scene = radiosity::scene::load_scene(&path).unwrap();
    let vf = run(scene, Method::Adaptive, None, |_| {});
    assert_eq!(vf.names, ["bottom", "top"]);
    assert!((vf.matrix.get(0, 1) - 0.199824895698).abs() < 1e-11);
    assert!((vf.emissivity[0] - 0.9).abs() < 1e-12);
}

/// An obstruction-only surface (View3D `O`) blocks like a surface but has no row/column.
#[test]
fn obstruction_only_surfaces_block_but_have_no_row() {
    let text = "T plates with a screen\nF 3\nV 1 0 0 0\nV 2 1 0 0\nV 3 1 1 0\nV 4 0 1 0\nV 5 0 0 1\nV 6 1 0 1\nV 7 1 1 1\nV 8 0 1 1\n\
        V 9 -1 -1 0.5\nV 10 0.5 -1 0.5\nV 11 0.5 2 0.5\nV 12 -1 2 0.5\n\
        S 1 1 2 3 4 0 0 0.9 bottom\nS 2 8 7 6 5 0 0 0.9 top\nXX 3 9 10 11 12 0 0 0.9 screen\nE\n";
    let path = std::path::Path::new("screen.vs3");
    let with = |kind: &str| {
        let (d, _) = radiosity::scene::vs3::parse_vs3(&text.replace("XX", kind), path).unwrap();
        run(Scene::from_desc(d).unwrap(), Method::Adaptive, None, |_| {})
    };
    let o = with("O");
    assert_eq!(o.names, ["bottom", "top"]);
    let s = with("S");
    assert_eq!(s.names.len(), 3);
    assert_eq!(o.matrix.get(0, 1), s.matrix.get(0, 1));
    // The exact value: from (x, y, 0) the screen's edge x = 0.5 at z = 0.5 hides the top
    // (z = 1) wherever x' < 1 − x, so F = ∫∫ F(dA → [1 − x, 1] × [0, 1]) dx dy, a smooth
    // integrand: Gauss–Legendre on 32 × 32 points (on [0, 1]) is exact to far below 1e-9.
    use glam::DVec3;
    let gl = radiosity::geom::gauss_legendre(32);
    let mut exact = 0.0;
    for &(x, wx) in gl {
        for &(y, wy) in gl {
            let x0 = 1.0 - x;
            let top = [DVec3::new(x0, 0.0, 1.0), DVec3::new(x0, 1.0, 1.0), DVec3::new(1.0, 1.0, 1.0), DVec3::new(1.0, 0.0, 1.0)];
            exact += wx * wy * radiosity::form_factor::analytic::point_factor(DVec3::new(x, y, 0.0), DVec3::Z, &top, -DVec3::Z);
        }
    }
    let got = o.matrix.get(0, 1);
    eprintln!("bottom → top behind the screen: {got:.9} vs exact {exact:.9}");
    assert!(((got - exact) / exact).abs() <= 1e-5, "{got} vs {exact}");
}

#[test]
fn monte_carlo_does_not_depend_on_the_thread_count() {
    let compute_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let scene = Scene::from_desc(radiosity::scene::builtin::cornell()).unwrap();
            run(scene, Method::MonteCarlo, Some(120.0), |o| o.mc_rays = 256).matrix
        })
    };
    assert_eq!(compute_with(1), compute_with(2));
}

#[test]
fn streamed_rows_equal_the_held_matrix() {
    let scene = Scene::from_desc(radiosity::scene::builtin::cornell()).unwrap();
    let settings = Settings {
        per: Per::Element,
        mesh_size: Some(150.0),
        form_factors: Options { method: Method::PointSampled, ..Default::default() },
        enclosure: false,
    };
    let job = Job::new(scene, settings).unwrap();
    let held = job.compute(None, &NoProgress).unwrap();
    let mut rows = Vec::new();
    let (diag, _) = job.stream(&NoProgress, &mut |r| {
        rows.push(r.to_vec());
        Ok(())
    }).unwrap();
    assert_eq!(rows.len(), held.matrix.n());
    for (i, r) in rows.iter().enumerate() {
        for (j, v) in r.iter().enumerate() {
            assert!((v - held.matrix.get(i, j)).abs() <= 1e-15, "[{i}][{j}]");
        }
    }
    assert_eq!(diag.row_sum_max, held.diagnostics.row_sum_max);
}

#[test]
fn a_matrix_too_large_for_memory_is_a_clear_error() {
    let scene = Scene::from_desc(radiosity::scene::builtin::cornell()).unwrap();
    let settings = Settings { per: Per::Element, mesh_size: Some(100.0), ..Default::default() };
    let job = Job::new(scene, settings).unwrap();
    let n = job.len() as u64;
    match job.compute(Some(1 << 16), &NoProgress) {
        Err(Error::TooLarge { needed, limit, .. }) => {
            assert_eq!(needed, n * n * 8);
            assert_eq!(limit, 1 << 16);
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
}

#[test]
fn analytic_warns_that_it_ignores_occlusion() {
    let cornell = Scene::from_desc(radiosity::scene::builtin::cornell()).unwrap();
    assert!(!run(cornell, Method::Analytic, None, |_| {}).stats.warnings.is_empty());
    assert!(run(vf_common::unit_cube(), Method::Analytic, None, |_| {}).stats.warnings.is_empty());
}

/// Every method drives the radiosity pipeline: the furnace (closed, uniform) must give
/// B = E / (1 − ρ) = 2π everywhere.
#[test]
fn every_method_solves_the_furnace() {
    use radiosity::pipeline::{solve_scene, Settings as PSettings};
    for method in Method::ALL {
        let scene = Scene::from_desc(radiosity::scene::builtin::furnace(0.5, 1.0)).unwrap();
        // Point-sampled needs small elements next to the cube's edges; the others are exact
        // (rows sum to 1 by construction or to their tolerance) on any mesh.
        let mesh_size = if method == Method::PointSampled { None } else { Some(0.25) };
        let settings = PSettings {
            mesh_size,
            form_factors: Options { method, ..Default::default() },
            solve: radiosity::solve::Options { tolerance: 1e-9, ..Default::default() },
            ..Default::default()
        };
        let solved = solve_scene(scene, &settings, &NoProgress).unwrap();
        let expect = 2.0 * std::f64::consts::PI;
        let tol = if method == Method::PointSampled { 1e-2 } else { 1e-4 };
        for b in &solved.solution.radiosity {
            assert!((b.x - expect).abs() <= tol * expect, "{}: B = {} vs {expect}", method.name(), b.x);
        }
    }
}

/// A scene of named objects, each a list of one-sided polygons.
fn objects(parts: Vec<(&str, Vec<Vec<glam::DVec3>>)>) -> Scene {
    use radiosity::scene::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
    let mut desc = SceneDesc {
        name: "case".into(),
        materials: vec![MaterialDesc::diffuse("grey", radiosity::Rgb::splat(0.5))],
        ..Default::default()
    };
    for (k, (name, polys)) in parts.into_iter().enumerate() {
        desc.objects.push(ObjectDesc { name: name.into(), loc: None });
        for vertices in polys {
            desc.polygons.push(PolygonDesc { uvs: Vec::new(), vertices, material: 0, object: k as u32, loc: None });
        }
    }
    Scene::from_desc(desc).unwrap()
}

/// The rectangle `o + [0, nu·du] × [0, nv·dv]` cut into `nu × nv` facets, counter-clockwise
/// about `du × dv`.
fn facets(o: glam::DVec3, du: glam::DVec3, dv: glam::DVec3, nu: usize, nv: usize) -> Vec<Vec<glam::DVec3>> {
    let mut out = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let p = o + du * i as f64 + dv * j as f64;
            out.push(vec![p, p + du, p + du + dv, p + dv]);
        }
    }
    out
}

/// Howell's C-11: directly opposed parallel rectangles `a × b` at distance `c`.
fn opposed_rectangles(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (x2, y2) = (x * x, y * y);
    2.0 / (std::f64::consts::PI * x * y)
        * (((1.0 + x2) * (1.0 + y2) / (1.0 + x2 + y2)).sqrt().ln() + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
            + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
            - x * x.atan()
            - y * y.atan())
}

/// A wall standing between the two halves of a pair of opposed unit squares (from the
/// floor to the ceiling along x = ½) leaves each half of the floor only the half of the
/// ceiling above it: F = F(½ × 1 opposed rectangles at distance 1), Howell's closed form.
/// The wall is given as 8 × 8 facets (merged into one occluder) and as one polygon, on
/// whole polygons and on elements.
#[test]
fn adaptive_wall_between_two_halves_is_the_closed_form() {
    use glam::DVec3;
    let exact = opposed_rectangles(0.5, 1.0, 1.0);
    for (n, mesh) in [(8, None), (1, None), (8, Some(0.25))] {
        let wall = facets(DVec3::new(0.5, -0.5, 0.0), DVec3::new(0.0, 2.0 / n as f64, 0.0), DVec3::new(0.0, 0.0, 1.0 / n as f64), n, n);
        let scene = objects(vec![
            ("from", facets(DVec3::ZERO, DVec3::X, DVec3::Y, 1, 1)),
            ("to", facets(DVec3::Z, DVec3::Y, DVec3::X, 1, 1)),
            ("wall", wall),
        ]);
        let f = run(scene, Method::Adaptive, mesh, |_| {}).matrix.get(0, 1);
        eprintln!("wall of {n}×{n} facets, mesh {mesh:?}: {f:.10} vs {exact:.10}");
        assert!(((f - exact) / exact).abs() <= 1e-5, "{n}×{n} facets, mesh {mesh:?}: {f} vs {exact}");
    }
}

/// A street corner as the urban-canyon script builds it (1 m facets): a ground facet sees
/// a wall facet across the street only past the corner of a building. The factor at the
/// default tolerance is the one the integral converges to (tolerance 1e-9) within the
/// tolerance, 1e-5 — before the sender was cut along the shadow's events it was 0.4 %
/// off here — and the building as 2 m facets gives the factor of the building as five
/// polygons. A facet straight behind the building gets exactly nothing.
#[test]
fn adaptive_street_corner_converges_at_its_tolerance() {
    use glam::DVec3;
    let v = DVec3::new;
    let ground = facets(v(12.0, 7.0, 0.0), DVec3::X, DVec3::Y, 1, 1);
    // Facing −x (towards the street), and one behind the building facing +x... both on
    // the far side of the street.
    let wall = vec![vec![v(28.0, 10.0, 5.0), v(28.0, 9.0, 5.0), v(28.0, 9.0, 6.0), v(28.0, 10.0, 6.0)]];
    let hidden = vec![vec![v(28.0, 14.0, 5.0), v(28.0, 13.0, 5.0), v(28.0, 13.0, 6.0), v(28.0, 14.0, 6.0)]];
    // nu × nz facets per wall (nu × nu on the roof).
    let building = |nu: usize, nz: usize| {
        let (su, sz) = (12.0 / nu as f64, 18.0 / nz as f64);
        let mut b = facets(v(8.0, 8.0, 18.0), DVec3::X * su, DVec3::Y * su, nu, nu); // roof
        b.extend(facets(v(8.0, 8.0, 0.0), DVec3::X * su, DVec3::Z * sz, nu, nz)); // south, −y
        b.extend(facets(v(20.0, 8.0, 0.0), DVec3::Y * su, DVec3::Z * sz, nu, nz)); // east, +x
        b.extend(facets(v(20.0, 20.0, 0.0), -DVec3::X * su, DVec3::Z * sz, nu, nz)); // north
        b.extend(facets(v(8.0, 20.0, 0.0), -DVec3::Y * su, DVec3::Z * sz, nu, nz)); // west
        b
    };
    let factors = |nu: usize, nz: usize, tol: f64, per: Per| {
        let scene = objects(vec![("ground", ground.clone()), ("wall", wall.clone()), ("hidden", hidden.clone()), ("building", building(nu, nz))]);
        let form_factors = Options {
            method: Method::Adaptive,
            adaptive_tolerance: tol,
            adaptive_max_evaluations: 10_000_000,
            ..Default::default()
        };
        // Per element (one per polygon): the first three rows are the three facets.
        let settings = Settings { per, mesh_size: Some(0.0), form_factors, enclosure: false };
        let vf = compute(scene, &settings, &NoProgress).unwrap();
        (vf.matrix.get(0, 1), vf.matrix.get(0, 2))
    };
    let default = radiosity::form_factor::adaptive::DEFAULT_TOLERANCE;
    let (f, h) = factors(6, 9, default, Per::Element);
    let (tight, _) = factors(6, 9, 1e-9, Per::Element);
    let (whole, hw) = factors(1, 1, default, Per::Object);
    eprintln!("street corner: {f:.12e} (tolerance 1e-9: {tight:.12e}; building as five polygons: {whole:.12e})");
    assert!(f > 0.0 && f < 2e-6, "{f}");
    assert!(((f - tight) / tight).abs() <= 1e-5, "{f} vs converged {tight}");
    assert!(((f - whole) / whole).abs() <= 1e-9, "{f} vs {whole}");
    assert_eq!((h, hw), (0.0, 0.0));
}
