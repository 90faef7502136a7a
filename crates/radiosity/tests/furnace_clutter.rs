//! The generalized furnace (issue 9): a closed two-sided room (ρ = 0.5, Ke = 1 everywhere)
//! with clutter inside — coincident duplicate boxes, touching boxes, interpenetrating
//! boxes, a thin slab, T-junctions. Every surface emits and reflects the same, so the exact
//! radiosity of every point that sees only surfaces is B = E/(1 − ρ) = 2π (L = 2), and no
//! element may exceed it (Σⱼ Fᵢⱼ ≤ 1 bounds the Neumann series).

use glam::DVec3;
use radiosity::form_factor::Method;
use radiosity::pipeline::{solve_scene, Settings};
use radiosity::scene::{MaterialDesc, ObjectDesc, PolygonDesc, Scene, SceneDesc};
use radiosity::solve::Solver;
use radiosity::{NoProgress, Rgb};

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// The six faces of an axis-aligned box, wound outward (or inward for a room).
fn box_faces(lo: DVec3, hi: DVec3, inward: bool) -> Vec<Vec<DVec3>> {
    let c = [
        v(lo.x, lo.y, lo.z),
        v(hi.x, lo.y, lo.z),
        v(hi.x, hi.y, lo.z),
        v(lo.x, hi.y, lo.z),
        v(lo.x, lo.y, hi.z),
        v(hi.x, lo.y, hi.z),
        v(hi.x, hi.y, hi.z),
        v(lo.x, hi.y, hi.z),
    ];
    let q = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [1, 2, 6, 5], [0, 4, 7, 3]];
    q.iter()
        .map(|f| {
            let mut p: Vec<DVec3> = f.iter().map(|&k| c[k]).collect();
            if inward {
                p.reverse();
            }
            p
        })
        .collect()
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
            d.polygons.push(PolygonDesc { vertices: p, material: 0, object: k as u32, loc: None });
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

#[test]
#[ignore]
fn survey() {
    let methods = [Method::PointSampled, Method::MonteCarlo, Method::Hemicube, Method::Adaptive];
    for (name, scene) in cases() {
        for m in methods {
            let mut s = Settings::default();
            s.form_factors.method = m;
            s.mesh_size = Some(0.1);
            s.solve.tolerance = 1e-9;
            s.solver = Solver::Jacobi;
            let solved = solve_scene(scene.clone(), &s, &NoProgress).unwrap();
            let f = solved.transport.as_ref().unwrap();
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
