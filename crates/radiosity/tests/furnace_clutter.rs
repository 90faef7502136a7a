//! The generalized furnace (issue 9): a closed two-sided room (ρ = 0.5, Ke = 1 everywhere)
//! with clutter inside — coincident duplicate boxes, touching boxes, interpenetrating
//! boxes, a thin slab, T-junctions. Every surface emits and reflects the same, so the exact
//! radiosity of every point that sees only surfaces is B = E/(1 − ρ) = 2π (L = 2), and no
//! element may exceed it (Σⱼ Fᵢⱼ ≤ 1 bounds the Neumann series).

use glam::DVec3;
mod common;
use common::box_faces;

use radiosity::form_factor::Method;
use radiosity::pipeline::{solve_all, solve_scene, Settings};
use radiosity::scene::{MaterialDesc, ObjectDesc, PolygonDesc, Scene, SceneDesc};
use radiosity::solve::Solver;
use radiosity::transport::Transport;
use radiosity::{NoProgress, Rgb};

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// A furnace room (unit cube, inward) with `clutter` (lists of polygons, one object each).
pub fn furnace_with(name: &str, clutter: Vec<Vec<Vec<DVec3>>>) -> Scene {
    let mut d = SceneDesc { name: name.into(), two_sided: true, ..Default::default() };
    d.materials.push(MaterialDesc { emission: Rgb::ONE, ..MaterialDesc::diffuse("grey", Rgb::splat(0.5)) });
    let mut objects = vec![box_faces(v(0., 0., 0.), v(1., 1., 1.), true)];
    objects.extend(clutter);
    for (k, polys) in objects.into_iter().enumerate() {
        d.objects.push(ObjectDesc { name: format!("o{k}"), loc: None });
        for p in polys {
            d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: p, material: 0, object: k as u32, loc: None });
        }
    }
    Scene::from_desc(d).unwrap()
}

pub fn cases() -> Vec<(&'static str, Scene)> {
    let b = |lo: DVec3, hi: DVec3| box_faces(lo, hi, false);
    vec![
        ("duplicate", furnace_with("duplicate", vec![b(v(0.3, 0., 0.3), v(0.6, 0.3, 0.6)), b(v(0.3, 0., 0.3), v(0.6, 0.3, 0.6))])),
        ("touching", furnace_with("touching", vec![b(v(0.2, 0., 0.2), v(0.5, 0.3, 0.5)), b(v(0.5, 0., 0.2), v(0.8, 0.3, 0.5))])),
        (
            "interpenetrating",
            furnace_with("interpenetrating", vec![b(v(0.2, 0., 0.2), v(0.6, 0.4, 0.6)), b(v(0.4, 0.2, 0.4), v(0.8, 0.6, 0.8))]),
        ),
        ("thin-slab", furnace_with("thin-slab", vec![b(v(0.2, 0.4, 0.2), v(0.8, 0.4005, 0.8))])),
        (
            "t-junction",
            // A small box on a large one: its bottom's edges end inside the top face (T-vertices).
            furnace_with("t-junction", vec![b(v(0.2, 0., 0.2), v(0.8, 0.2, 0.8)), b(v(0.35, 0.2, 0.35), v(0.65, 0.5, 0.65))]),
        ),
    ]
}

/// A two-sided lamp 1 cm under the ceiling of a room open at the front (the McGuire
/// Cornell box with `--two-sided`): the lamp's back emits into the gap, and the ceiling's
/// cells above it count as covered (every probe meets a generated back copy). Monte Carlo
/// dropped every ray of a partly covered ceiling element that met the lamp's back copy, as
/// if each started in the covered part, and let 54.9 % of the McGuire box's light escape
/// against 44.6 % point-sampled and 44.5 % hemicube (2026-12-05); it now drops the rays
/// that start in a covered cell (44.4 %). Every method must let out the same share.
#[test]
fn two_sided_lamp_under_the_ceiling_lets_out_the_same_light_with_every_method() {
    let mut d = SceneDesc { name: "lamp-gap".into(), two_sided: true, ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    d.materials.push(MaterialDesc { emission: Rgb::splat(10.0), ..MaterialDesc::diffuse("lamp", Rgb::splat(0.5)) });
    let room: Vec<Vec<DVec3>> = box_faces(v(0., 0., 0.), v(1., 1., 1.), true).into_iter().filter(|f| !f.iter().all(|p| p.z == 1.0)).collect();
    assert_eq!(room.len(), 5);
    let lamp = vec![vec![v(0.35, 0.99, 0.35), v(0.65, 0.99, 0.35), v(0.65, 0.99, 0.65), v(0.35, 0.99, 0.65)]];
    for (k, (polys, material)) in [(room, 0), (lamp, 1)].into_iter().enumerate() {
        d.objects.push(ObjectDesc { name: format!("o{k}"), loc: None });
        for p in polys {
            d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: p, material, object: k as u32, loc: None });
        }
    }
    let scene = Scene::from_desc(d).unwrap();
    let escaped = |m: Method| {
        let mut s = Settings { mesh_size: Some(0.1), ..Default::default() };
        s.form_factors.method = m;
        let e = solve_scene(scene.clone(), &s, &NoProgress).unwrap().energy();
        e.escaped[1] / e.emitted[1]
    };
    let reference = escaped(Method::PointSampled);
    for m in [Method::MonteCarlo, Method::Hemicube] {
        let x = escaped(m);
        eprintln!("{}: escaped {:.2} % (point-sampled {:.2} %)", m.name(), 100.0 * x, 100.0 * reference);
        assert!((x - reference).abs() <= 0.01, "{}: escaped {:.2} %, point-sampled {:.2} %", m.name(), 100.0 * x, 100.0 * reference);
    }
}

/// RenderPark office2's lamp housing, a tray with walls of two shells 0.002 apart and the
/// lamp 0.018 under its floor, alone in a closed two-sided room. Monte Carlo rays start on
/// the sender's plane rounded to f32, a hair behind its own generated back copy, and met it
/// at once: 8 % of some housing elements' rows went to their own back sides, and 5.16 % of
/// the light escaped the closed room (now 0.18 %; office2 `--two-sided`: 4.83 % against
/// stochastic Jacobi's 4.56 %, now 4.55 %). Rays now skip everything in the plane they
/// leave. Point-sampled (0.84 %) and hemicube (0.65 %) rows are printed, not held here.
#[test]
fn double_walled_lamp_housing_keeps_a_closed_room_closed_with_monte_carlo() {
    let mut d = SceneDesc { name: "lamp-housing".into(), two_sided: true, ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    d.materials.push(MaterialDesc { emission: Rgb::splat(100.0), ..MaterialDesc::diffuse("lamp", Rgb::splat(0.4)) });
    let q = |p: [[f64; 3]; 4]| p.iter().map(|a| v(a[0], a[1], a[2])).collect::<Vec<DVec3>>();
    // office2.obj lines 1867–1876 (outer and inner shell) and 1879 (the lamp).
    let housing = vec![
        q([[2.5, 1.4, 2.68], [2.5, 1.46, 2.76], [1.1, 1.46, 2.76], [1.1, 1.4, 2.68]]),
        q([[1.1, 1.4, 2.68], [1.1, 1.46, 2.76], [1.1, 1.54, 2.76], [1.1, 1.6, 2.68]]),
        q([[2.5, 1.54, 2.76], [2.5, 1.6, 2.68], [1.1, 1.6, 2.68], [1.1, 1.54, 2.76]]),
        q([[2.5, 1.46, 2.76], [2.5, 1.4, 2.68], [2.5, 1.6, 2.68], [2.5, 1.54, 2.76]]),
        q([[2.5, 1.46, 2.76], [2.5, 1.54, 2.76], [1.1, 1.54, 2.76], [1.1, 1.46, 2.76]]),
        q([[1.102, 1.462, 2.758], [2.498, 1.462, 2.758], [2.498, 1.402, 2.678], [1.102, 1.402, 2.678]]),
        q([[1.102, 1.462, 2.758], [1.102, 1.402, 2.678], [1.102, 1.598, 2.678], [1.102, 1.538, 2.758]]),
        q([[2.498, 1.598, 2.678], [2.498, 1.538, 2.758], [1.102, 1.538, 2.758], [1.102, 1.598, 2.678]]),
        q([[2.498, 1.462, 2.758], [2.498, 1.538, 2.758], [2.498, 1.598, 2.678], [2.498, 1.402, 2.678]]),
        q([[1.102, 1.538, 2.758], [2.498, 1.538, 2.758], [2.498, 1.462, 2.758], [1.102, 1.462, 2.758]]),
    ];
    let lamp = vec![q([[2.45, 1.48, 2.74], [1.15, 1.48, 2.74], [1.15, 1.52, 2.74], [2.45, 1.52, 2.74]])];
    let room = box_faces(v(0.9, 1.2, 2.3), v(2.7, 1.8, 2.9), true);
    for (k, (polys, material)) in [(room, 0), (housing, 0), (lamp, 1)].into_iter().enumerate() {
        d.objects.push(ObjectDesc { name: format!("o{k}"), loc: None });
        for p in polys {
            d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: p, material, object: k as u32, loc: None });
        }
    }
    let scene = Scene::from_desc(d).unwrap();
    for m in [Method::MonteCarlo, Method::PointSampled, Method::Hemicube] {
        let mut s = Settings { mesh_size: Some(0.1), ..Default::default() };
        s.form_factors.method = m;
        s.transport = radiosity::transport::Kind::Rows;
        let e = solve_scene(scene.clone(), &s, &NoProgress).unwrap().energy();
        let x = e.escaped[1] / e.emitted[1];
        eprintln!("{}: escaped {:.2} % of a closed room", m.name(), 100.0 * x);
        if m == Method::MonteCarlo {
            assert!(x.abs() <= 0.005, "monte-carlo: {:.2} % of the light escaped a closed room", 100.0 * x);
        }
    }
}

/// Diagnostic, run by hand: per case and method, the guard's counts and the worst row with
/// its largest entries. `MESH=0.25` sets the mesh size (default 0.1), `ONLY_ADAPTIVE=1`
/// runs adaptive alone, `ONLY_GUARD=1` skips the solve.
#[test]
#[ignore]
fn survey() {
    let methods = if std::env::var("ONLY_ADAPTIVE").is_ok() { vec![Method::Adaptive] } else { vec![Method::PointSampled, Method::MonteCarlo, Method::Hemicube, Method::Adaptive] };
    for (name, scene) in cases() {
        for &m in &methods {
            let mut s = Settings::default();
            s.form_factors.method = m;
            s.mesh_size = Some(std::env::var("MESH").ok().and_then(|x| x.parse().ok()).unwrap_or(0.1));
            s.solve.tolerance = 1e-9;
            s.solver = Solver::Jacobi;
            let solved = match solve_scene(scene.clone(), &s, &NoProgress) {
                Ok(x) => x,
                Err(e) => {
                    println!("{name:18} {:14} ERROR {e}", m.name());
                    continue;
                }
            };
            let g = &solved.ff_stats.as_ref().unwrap().guard;
            println!("{name:18} {:14} guard: corrected {} dropped {} raw max {:.4} at {:?}", m.name(), g.rows_corrected, g.entries_dropped, g.max_row_sum, g.worst_row);
            if let Some(w) = g.worst_row {
                let w = w as usize;
                let e = &solved.mesh.elements[w];
                let p = &solved.scene.polygons[e.patch as usize];
                println!("   worst el {w} patch {} obj {} back {} c {:?} n {:?} open {:.3} cells {:016x}", e.patch, p.object, p.back_side, e.centroid, e.normal, solved.receivers.open_fraction[w], solved.receivers.open_cells[w]);
                let f = solved.transport.as_ref().unwrap().rows().unwrap();
                let (cols, vals) = f.row(w); let mut row: Vec<(u32, f64)> = cols.iter().copied().zip(vals.iter().map(|x| *x as f64)).collect();
                row.sort_by(|a, b| b.1.total_cmp(&a.1));
                for (j, x) in row.iter().take(6) {
                    let ej = &solved.mesh.elements[*j as usize];
                    let pj = &solved.scene.polygons[ej.patch as usize];
                    println!("     -> {j} f {x:.4} patch {} obj {} back {} c {:?} n {:?} open {:.3}", ej.patch, pj.object, pj.back_side, ej.centroid, ej.normal, solved.receivers.open_fraction[*j as usize]);
                }
            }
            if std::env::var("ONLY_GUARD").is_ok() { continue; }
            let f = solved.transport.as_ref().unwrap().rows().unwrap();
            let n = solved.mesh.len();
            let mut worst = (0.0, 0);
            for i in 0..n {
                let r = f.row_sum(i);
                if r > worst.0 {
                    worst = (r, i);
                }
            }
            let bound = 2.0 * std::f64::consts::PI;
            let bmax = solved.solution.radiosity.iter().map(|b| b.max_element()).fold(0.0, f64::max);
            let above = solved.solution.radiosity.iter().filter(|b| b.max_element() > bound * 1.01).count();
            let e = &solved.mesh.elements[worst.1];
            let p = &solved.scene.polygons[e.patch as usize];
            println!(
                "{name:18} {:14} n={n:5} maxrow={:.4} (el {} patch {} obj {} back {} c {:?} open {:.3}) maxB/bound={:.4} above={above} it={} res={:.2e} imb={:.1e}",
                m.name(),
                worst.0,
                worst.1,
                e.patch,
                p.object,
                p.back_side,
                e.centroid,
                solved.receivers.open_fraction[worst.1],
                bmax / bound,
                solved.solution.stats.iterations,
                solved.solution.stats.residual,
                solved.solution.energy.relative_imbalance()
            );
        }
    }
}

/// Distance from `x` to a convex planar polygon.
fn distance_to_polygon(x: DVec3, v: &[DVec3], n: DVec3) -> f64 {
    let d = n.dot(x - v[0]);
    let y = x - n * d;
    let inside = (0..v.len()).all(|k| (v[(k + 1) % v.len()] - v[k]).cross(y - v[k]).dot(n) >= 0.0);
    if inside {
        return d.abs();
    }
    (0..v.len())
        .map(|k| {
            let (a, b) = (v[k], v[(k + 1) % v.len()]);
            let t = ((x - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
            (x - (a + (b - a) * t)).length()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Surfaces (input polygons) "not in contact with another": every corner and centroid of
/// their elements farther than `gap` from every polygon of another object (the walls of
/// one room meet at its edges) but their own two-sided twin,
/// every element wholly open, and not the outside of the furnace room (which sees nothing:
/// B = E there).
fn free_patches(solved: &radiosity::pipeline::Solved, gap: f64, require_open: bool) -> Vec<u32> {
    let (scene, mesh) = (&solved.scene, &solved.mesh);
    let room = |o: u32| o == 0 || scene.objects[o as usize].name == "furnace-room";
    // Objects touching another (a vertex within `gap` of another object's polygon): the
    // inside of such a solid is a cavity closed by the contact, not a free surface.
    let touches: Vec<bool> = (0..scene.objects.len() as u32)
        .map(|o| {
            scene.polygons.iter().filter(|p| p.object == o).any(|p| {
                p.vertices.iter().any(|x| {
                    scene.polygons.iter().any(|q| q.object != o && distance_to_polygon(*x, &q.vertices, q.normal) <= gap)
                })
            })
        })
        .collect();
    (0..scene.polygons.len() as u32)
        .filter(|&pi| {
            let own = &scene.polygons[pi as usize];
            if own.back_side && (room(own.object) || touches[own.object as usize]) {
                return false;
            }
            let pe = mesh.patches[pi as usize];
            (pe.first..pe.first + pe.count).all(|i| {
                let e = &mesh.elements[i as usize];
                let (c, nc) = e.corners(&mesh.positions);
                (!require_open || solved.receivers.open_fraction[i as usize] >= 1.0)
                    && c[..nc].iter().chain(std::iter::once(&e.centroid)).all(|x| {
                        scene.polygons.iter().enumerate().all(|(_, p)| {
                            p.object == own.object
                                || (p.normal.dot(own.normal) < -0.999999 && (p.centroid() - own.centroid()).length() < 1e-9)
                                || distance_to_polygon(*x, &p.vertices, p.normal) > gap
                        })
                    })
            })
        })
        .collect()
}

/// Every solver on one scene and method: no element above the bound 2π (E/(1 − ρ), the
/// method's tolerance on top), the energy balance closed to 1e-6, and every element not in
/// contact within 1 % of 2π (deterministic solvers; the stochastic ones by the mean of
/// those elements, per object).
pub fn check_furnace(name: &str, scene: Scene, method: Method, mesh_size: f64) {
    check_furnace_with(name, scene, method, mesh_size, |_| {});
}

/// As [`check_furnace`], with `tune` applied to the settings last.
pub fn check_furnace_with(name: &str, scene: Scene, method: Method, mesh_size: f64, tune: impl FnOnce(&mut Settings)) {
    let mut s = Settings::default();
    s.form_factors.method = method;
    s.mesh_size = Some(mesh_size);
    s.solve.tolerance = 1e-9;
    s.solve.max_iterations = 200;
    // Stochastic solvers: 2M rays per iteration, so that their noise (≈ 0.4 % per
    // surface of ordinary size here) stays inside the 1 % asked.
    s.solve.rays = Some(2_000_000);
    tune(&mut s);
    let t = std::time::Instant::now();
    let cmp = solve_all(scene, &s, &NoProgress).unwrap_or_else(|e| panic!("{name} {}: {e}", method.name()));
    let exact = 2.0 * std::f64::consts::PI;
    // "In contact": within half an element, or 2 % of the scene, of another object.
    // A real model inside the furnace room: the room's walls see only the model's outside,
    // which is the back of its (inward-wound) walls, so the coverage test calls them
    // covered; they still gather, and are held to 1 % all the same.
    let model = cmp.solved.scene.objects.iter().any(|o| o.name == "furnace-room");
    let free = free_patches(&cmp.solved, (0.5 * mesh_size).min(0.02 * cmp.solved.scene.diagonal()), !model);
    assert!(!free.is_empty(), "{name}: no surface free of contact");
    let g = &cmp.solved.ff_stats.as_ref().unwrap().guard;
    eprintln!(
        "{name} {}: {} elements, {} free surfaces, rows corrected {} (raw max {:.4}), {:.1} s",
        method.name(),
        cmp.solved.mesh.len(),
        free.len(),
        g.rows_corrected,
        g.max_row_sum,
        t.elapsed().as_secs_f64()
    );
    for w in &cmp.solved.ff_stats.as_ref().unwrap().warnings {
        eprintln!("  {w}");
    }
    let mut failures = Vec::new();
    for run in &cmp.runs {
        let sol = run.outcome.as_ref().unwrap_or_else(|e| panic!("{name} {} {}: {e}", method.name(), run.solver));
        let b = &sol.radiosity;
        if run.solver.is_stochastic() {
            // Per-element estimates carry ray noise (a 0.5 mm slab edge gets a handful of
            // rays): the bound is held by every object's area-weighted mean of its open
            // area, within 1 % plus four standard deviations of its ray estimate. In a
            // furnace every ray lands, so an object with open area A_o of A in all gets
            // about R·A_o/A of the R rays per iteration, and the half of B that is
            // reflected carries their relative noise 1/√hits.
            let open = cmp.solved.receivers.open_areas(&cmp.solved.mesh);
            let total: f64 = open.iter().sum();
            let rays = s.solve.rays.unwrap() as f64;
            let mut sums = vec![(0.0, 0.0); cmp.solved.scene.objects.len()];
            for (i, e) in cmp.solved.mesh.elements.iter().enumerate() {
                let o = cmp.solved.scene.polygons[e.patch as usize].object as usize;
                sums[o].0 += open[i] * b[i].max_element();
                sums[o].1 += open[i];
            }
            for (o, (num, den)) in sums.iter().enumerate().filter(|x| x.1 .1 > 0.0) {
                let mean = num / den;
                let sigma = 0.5 / (rays * den / total).sqrt();
                let tol = 0.01 + 4.0 * sigma;
                assert!(
                    mean <= exact * (1.0 + tol),
                    "{name} {} {}: object {o} ({}) mean B {mean} above the bound {exact} (tolerance {tol:.4})",
                    method.name(),
                    run.solver,
                    cmp.solved.scene.objects[o].name
                );
            }
        } else {
            let max = b.iter().map(|x| x.max_element()).fold(0.0, f64::max);
            assert!(max <= exact * (1.0 + 1e-6), "{name} {} {}: max B {max} above the bound {exact}", method.name(), run.solver);
        }
        let imb = sol.energy.relative_imbalance();
        assert!(imb <= 1e-6, "{name} {} {}: energy imbalance {imb:.3e}", method.name(), run.solver);
        // Every free surface's area-weighted mean within 1 % of 2π.
        let mesh = &cmp.solved.mesh;
        let mut areas: Vec<f64> = free.iter().map(|&p| cmp.solved.scene.polygons[p as usize].area).collect();
        areas.sort_by(f64::total_cmp);
        let median = areas[areas.len() / 2];
        for &pi in &free {
            // A ray estimate of a surface 1/20 the median size (the 0.5 mm edges of the thin
            // slab) carries noise beyond 1 % at any sensible ray count: not held to it.
            if run.solver.is_stochastic() && cmp.solved.scene.polygons[pi as usize].area < 0.05 * median {
                continue;
            }
            let pe = mesh.patches[pi as usize];
            let (mut num, mut den) = (0.0, 0.0);
            for i in pe.first as usize..(pe.first + pe.count) as usize {
                num += mesh.elements[i].area * b[i].max_element();
                den += mesh.elements[i].area;
            }
            let off = (num / den / exact - 1.0).abs();
            // Known limit (docs/RELIABILITY.md): the furnace room's walls around a real
            // model see only the back of the model's inward-wound walls, so the coverage
            // test calls most of them covered; the stochastic solvers send and receive
            // through open cells only, and the walls' partly covered elements lose the
            // light of their covered cells (office2: up to 1.1 % low). Adaptive factors
            // integrate a partly covered receiver over its open cells, so the model's
            // outside misses the walls' covered cells (office2: a wall 1.65 % low).
            // Held to 2 % there.
            let room_wall = model && cmp.solved.scene.objects[cmp.solved.scene.polygons[pi as usize].object as usize].name == "furnace-room";
            let allowed = if (run.solver.is_stochastic() || method == Method::Adaptive) && room_wall { 0.02 } else { 0.01 };
            if off > allowed {
                failures.push(format!(
                    "{name} {} {}: free surface {} is {:.3} % off 2π",
                    method.name(),
                    run.solver,
                    radiosity::pipeline::element_place(&cmp.solved.scene, mesh, pe.first as usize),
                    100.0 * off
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{} surface(s) off:\n{}", failures.len(), failures.join("\n"));
}

macro_rules! furnace_tests {
    ($($test:ident: $case:expr, $method:expr;)*) => {$(
        #[test]
        fn $test() {
            let (name, scene) = cases().into_iter().find(|c| c.0 == $case).unwrap();
            // Adaptive integration is exact and slow: a coarser mesh.
            let size = if $method == Method::Adaptive { 0.25 } else { 0.125 };
            check_furnace(name, scene, $method, size);
        }
    )*};
}

furnace_tests! {
    furnace_duplicate_boxes_point_sampled: "duplicate", Method::PointSampled;
    furnace_duplicate_boxes_monte_carlo: "duplicate", Method::MonteCarlo;
    furnace_duplicate_boxes_hemicube: "duplicate", Method::Hemicube;
    furnace_duplicate_boxes_adaptive: "duplicate", Method::Adaptive;
    furnace_touching_boxes_point_sampled: "touching", Method::PointSampled;
    furnace_touching_boxes_monte_carlo: "touching", Method::MonteCarlo;
    furnace_touching_boxes_hemicube: "touching", Method::Hemicube;
    furnace_touching_boxes_adaptive: "touching", Method::Adaptive;
    furnace_interpenetrating_boxes_point_sampled: "interpenetrating", Method::PointSampled;
    furnace_interpenetrating_boxes_monte_carlo: "interpenetrating", Method::MonteCarlo;
    furnace_interpenetrating_boxes_hemicube: "interpenetrating", Method::Hemicube;
    furnace_interpenetrating_boxes_adaptive: "interpenetrating", Method::Adaptive;
    furnace_thin_slab_point_sampled: "thin-slab", Method::PointSampled;
    furnace_thin_slab_monte_carlo: "thin-slab", Method::MonteCarlo;
    furnace_thin_slab_hemicube: "thin-slab", Method::Hemicube;
    furnace_thin_slab_adaptive: "thin-slab", Method::Adaptive;
    furnace_t_junctions_point_sampled: "t-junction", Method::PointSampled;
    furnace_t_junctions_monte_carlo: "t-junction", Method::MonteCarlo;
    furnace_t_junctions_hemicube: "t-junction", Method::Hemicube;
    furnace_t_junctions_adaptive: "t-junction", Method::Adaptive;
}

/// A real model's geometry inside a closed furnace room, the room two-sided like the model
/// (see [`common::model_in_furnace`]).
fn model_in_furnace(rel: &str) -> Option<Scene> {
    common::model_in_furnace(rel, false)
}

macro_rules! model_furnace_tests {
    ($($(#[$attr:meta])* $test:ident: $rel:expr, $method:expr, $frac:expr;)*) => {$(
        #[test]
        $(#[$attr])*
        fn $test() {
            let Some(scene) = model_in_furnace($rel) else { return };
            let size = scene.diagonal() / $frac;
            // Adaptive: a relative tolerance of 1e-3 per pair (the default 1e-5 is the
            // thermal reference), well inside the 1 % asked of every surface.
            check_furnace_with($rel, scene, $method, size, |s| s.form_factors.adaptive_tolerance = 1e-3);
        }
    )*};
}

// office2 and the classroom at diag/12 (2,130 and 12,458 elements; the classroom takes
// 37 s point-sampled, 31 s Monte Carlo and 147 s hemicube with every solver on two cores).
// Adaptive integration: office2 at diag/6 (1,190 elements) in 378 s on two cores
// (2026-12-01; before the pair cache and occluder ordering it had not finished in 12
// minutes). The classroom (10,500 polygons, two-sided) runs with `--ignored`: measured
// on 40 random rows it would take over a day on two cores; a sample of its rows runs in
// `furnace_classroom_adaptive_rows_sum_to_one`.
model_furnace_tests! {
    furnace_office2_point_sampled: "scenes/renderpark-office2/office2.obj", Method::PointSampled, 12.0;
    furnace_office2_monte_carlo: "scenes/renderpark-office2/office2.obj", Method::MonteCarlo, 12.0;
    furnace_office2_hemicube: "scenes/renderpark-office2/office2.obj", Method::Hemicube, 12.0;
    furnace_office2_adaptive: "scenes/renderpark-office2/office2.obj", Method::Adaptive, 6.0;
    furnace_classroom_point_sampled: "scenes/renderpark-classroom/classroom.obj", Method::PointSampled, 12.0;
    furnace_classroom_monte_carlo: "scenes/renderpark-classroom/classroom.obj", Method::MonteCarlo, 12.0;
    furnace_classroom_hemicube: "scenes/renderpark-classroom/classroom.obj", Method::Hemicube, 12.0;
    #[ignore] furnace_classroom_adaptive: "scenes/renderpark-classroom/classroom.obj", Method::Adaptive, 12.0;
}

/// The classroom's full adaptive furnace (`furnace_classroom_adaptive`) is an overnight
/// job: 40 random rows took a median of 2.9 s and a mean of 19 s each on one core, up to
/// 229 s for a large element behind many occluders (2026-12-05), so 12 458 rows would take
/// over a day on two cores. Its rows themselves are what bounds transport, so a sample of
/// them runs here: every 3 000th element of the classroom in the furnace room (diag/12,
/// tolerance 1e-3) and the first free element (nothing covers it) from there. A closed room's rows sum to one: each free element's within 1 %, no
/// row above one by more than the tolerance. (The 40 random rows: free ones 0.9943 to
/// 1.0000, none above 1.00000.)
#[test]
fn furnace_classroom_adaptive_rows_sum_to_one() {
    let Some(scene) = model_in_furnace("scenes/renderpark-classroom/classroom.obj") else { return };
    let mesh = radiosity::mesh::mesh_uniform(&scene, scene.diagonal() / 12.0);
    let rays = radiosity::accel::SceneRays::new(&scene.polygons);
    let receivers = radiosity::mesh::Receivers::compute(&scene, &mesh, &rays);
    let opts = radiosity::form_factor::Options { method: Method::Adaptive, adaptive_tolerance: 1e-3, ..Default::default() };
    // Every 3 000th element, and the first free one at or after it.
    let mut rows: Vec<u32> = Vec::new();
    for k in (0..mesh.len()).step_by(3000) {
        rows.push(k as u32);
        if let Some(f) = (k..mesh.len()).find(|&i| receivers.open_fraction[i] >= 1.0) {
            rows.push(f as u32);
        }
    }
    rows.sort_unstable();
    rows.dedup();
    let mut free = 0;
    radiosity::form_factor::for_each_row(&scene, &mesh, &rays, &receivers, &opts, Some(&rows), &NoProgress, &mut |i, row| {
        let sum: f64 = row.iter().map(|x| x.1).sum();
        let open = receivers.open_fraction[i];
        eprintln!("row {i}: sum {sum:.5}, open {open:.4}");
        assert!(row.iter().all(|x| x.1.is_finite() && x.1 >= 0.0), "row {i}");
        assert!(sum <= 1.0 + 1e-3, "row {i} sums to {sum}");
        if open >= 1.0 {
            free += 1;
            assert!((sum - 1.0).abs() <= 0.01, "free row {i} sums to {sum}");
        }
        Ok(())
    })
    .unwrap();
    assert!(free >= 4, "only {free} free rows in the sample");
}

/// Diagnostic, run by hand: the rows of a real model in the furnace room, computed alone.
/// `MODEL` (default office2), `FRAC` (mesh size = diagonal / FRAC, default 6), `ROWS`
/// (comma-separated element indices) or `PATCH` (a polygon's elements), `TOL` (adaptive tolerance, default 1e-3), `METHOD`.
#[test]
#[ignore]
fn model_rows() {
    let rel = std::env::var("MODEL").unwrap_or_else(|_| "scenes/renderpark-office2/office2.obj".into());
    let Some(scene) = model_in_furnace(&rel) else { return };
    let frac: f64 = std::env::var("FRAC").ok().and_then(|x| x.parse().ok()).unwrap_or(6.0);
    let mesh = radiosity::mesh::mesh_uniform(&scene, scene.diagonal() / frac);
    let rays = radiosity::accel::SceneRays::new(&scene.polygons);
    let receivers = radiosity::mesh::Receivers::compute(&scene, &mesh, &rays);
    let mut opts = radiosity::form_factor::Options::default();
    opts.method = std::env::var("METHOD").ok().and_then(|m| m.parse::<Method>().ok()).unwrap_or(Method::Adaptive);
    opts.adaptive_tolerance = std::env::var("TOL").ok().and_then(|x| x.parse().ok()).unwrap_or(1e-3);
    // `LOW=x`: every row, listing those summing below x (a closed furnace sums to 1).
    let low: Option<f64> = std::env::var("LOW").ok().and_then(|x| x.parse().ok());
    if let Some(low) = low {
        let mut n = 0;
        radiosity::form_factor::for_each_row(&scene, &mesh, &rays, &receivers, &opts, None, &NoProgress, &mut |i, row| {
            let sum: f64 = row.iter().map(|x| x.1).sum();
            if sum < low {
                n += 1;
                println!("low row {i} sum {sum:.5} open {:.4} ({})", receivers.open_fraction[i], radiosity::pipeline::element_place(&scene, &mesh, i));
            }
            Ok(())
        })
        .unwrap();
        println!("{n} rows below {low} of {}", mesh.len());
        return;
    }
    let mut rows: Vec<u32> = std::env::var("ROWS").unwrap_or_else(|_| "0".into()).split(',').map(|x| x.trim().parse().unwrap()).collect();
    // `PATCH=p`: every element of polygon p instead.
    if let Some(p) = std::env::var("PATCH").ok().and_then(|x| x.parse::<usize>().ok()) {
        let pe = mesh.patches[p];
        rows = (pe.first..pe.first + pe.count).collect();
    }
    // `TIMES=1`: each row alone (two at a time), with the seconds it took.
    if std::env::var("TIMES").is_ok() {
        use rayon::prelude::*;
        rows.par_iter().for_each(|&i| {
            let t = std::time::Instant::now();
            let mut sum = 0.0;
            radiosity::form_factor::for_each_row(&scene, &mesh, &rays, &receivers, &opts, Some(&[i]), &NoProgress, &mut |_, row| {
                sum = row.iter().map(|x| x.1).sum();
                Ok(())
            })
            .unwrap();
            println!("time row {i}: {:.2} s, sum {sum:.5}, open {:.4} ({})", t.elapsed().as_secs_f64(), receivers.open_fraction[i as usize], radiosity::pipeline::element_place(&scene, &mesh, i as usize));
        });
        return;
    }
    radiosity::form_factor::for_each_row(&scene, &mesh, &rays, &receivers, &opts, Some(&rows), &NoProgress, &mut |i, row| {
        let e = &mesh.elements[i];
        let sum: f64 = row.iter().map(|x| x.1).sum();
        println!("row {i} ({}): sum {sum:.5}, open {:.4}, n {:?}", radiosity::pipeline::element_place(&scene, &mesh, i), receivers.open_fraction[i], e.normal);
        let mut r = row.to_vec();
        r.sort_by(|a, b| b.1.total_cmp(&a.1));
        for (j, f) in r.iter().take(8) {
            println!("   -> {j} f {f:.5} open {:.4} ({})", receivers.open_fraction[*j as usize], radiosity::pipeline::element_place(&scene, &mesh, *j as usize));
        }
        Ok(())
    })
    .unwrap();
    println!("{} elements", mesh.len());
}

/// Issue 9, office2's raw row sum of 9.0: elements smaller than the coverage test's fine
/// grid threshold (√area below 1/200 of the scene's diagonal) that a contact crosses kept
/// "every cell open" with an open fraction of 1/9, so adaptive factors integrated the whole
/// element and divided by its open area. Two interpenetrating boxes 6 mm on a side in the
/// unit furnace room: every partly covered element's open pieces hold exactly its open
/// area, no adaptive row sums above 1 by more than the tolerance before the guard, and the
/// furnace holds.
#[test]
fn furnace_small_interpenetrating_boxes_adaptive() {
    let b = |lo: DVec3, hi: DVec3| box_faces(lo, hi, false);
    let scene = furnace_with(
        "small-interpenetrating",
        vec![b(v(0.5, 0.0, 0.5), v(0.506, 0.006, 0.506)), b(v(0.503, 0.002, 0.503), v(0.509, 0.008, 0.509))],
    );
    let mesh = radiosity::mesh::mesh_uniform(&scene, 0.25);
    let rays = radiosity::accel::SceneRays::new(&scene.polygons);
    let rec = radiosity::mesh::Receivers::compute(&scene, &mesh, &rays);
    let mut partly = 0;
    for (i, e) in mesh.elements.iter().enumerate() {
        let f = rec.open_fraction[i];
        if f > 0.0 && f < 1.0 {
            partly += 1;
            let a: f64 = rec.open_pieces(&mesh, i).iter().map(|p| 0.5 * radiosity::scene::newell_normal(p).length()).sum();
            assert!((a - f * e.area).abs() <= 1e-9 * e.area, "element {i}: open pieces {a:.6e}, open area {:.6e}", f * e.area);
        }
    }
    assert!(partly >= 4, "only {partly} partly covered elements: the case does not test small elements");
    let mut s = Settings::default();
    s.form_factors.method = Method::Adaptive;
    s.form_factors.adaptive_tolerance = 1e-3;
    s.mesh_size = Some(0.25);
    let solved = solve_scene(scene.clone(), &s, &NoProgress).unwrap();
    let g = &solved.ff_stats.as_ref().unwrap().guard;
    eprintln!("{partly} partly covered elements; raw max row sum {:.5}, rows corrected {}", g.max_row_sum, g.rows_corrected);
    assert!(g.max_row_sum <= 1.0 + 1e-2, "raw max row sum {:.4}", g.max_row_sum);
    check_furnace_with("small-interpenetrating", scene, Method::Adaptive, 0.25, |s| s.form_factors.adaptive_tolerance = 1e-3);
}
