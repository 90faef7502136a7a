//! A uniform sky (`[sky]`, `--sky`): closed forms and equivalences that could fail.
//!
//! - Under a sky of radiance L, a surface that sees only sky has L_out = ρ·L; inside an
//!   open box with black walls the floor's mean radiance is ρ·L·F(floor → opening), the
//!   parallel-squares view factor.
//! - A uniform sky seen through an opening is the same light as a black lid of emitted
//!   radiance L over that opening: an open box with grey walls under the sky must match the
//!   same box closed by such a lid, object by object (interreflections included).
//! - No sky light enters a closed room.
//! - The final gather shows L where camera rays leave the scene and ρ·L on a surface that
//!   sees only sky, exactly, whether the indirect light is gathered or interpolated.

mod common;

use std::f64::consts::PI;

use glam::DVec3;
use radiosity::pipeline::{solve_scene, Settings, Solved};
use radiosity::render::gouraud::ElementTracer;
use radiosity::scene::{Camera, MaterialDesc, ObjectDesc, PolygonDesc, Scene, SceneDesc, Sky};
use radiosity::solve::Solver;
use radiosity::transport::Kind;
use radiosity::{form_factor, NoProgress, Rgb};

/// View factor between equal, parallel, coaxial squares of side `a` at distance `c`
/// (Howell's catalogue C-11 with X = Y = a/c).
fn parallel_squares(a: f64, c: f64) -> f64 {
    let x = a / c;
    let q = (1.0 + x * x).sqrt();
    2.0 / (PI * x * x)
        * (((1.0 + x * x).powi(2) / (1.0 + 2.0 * x * x)).sqrt().ln() + 2.0 * x * q * (x / q).atan() - 2.0 * x * x.atan())
}

/// A unit-square floor (y = 0, facing up) with four inward walls of height `h`; walls of
/// reflectance `wall_rho`, floor 0.5; optionally a lid at y = h facing down, emitting
/// `lid` radiance with reflectance 0; optionally the sky.
fn open_box(h: f64, wall_rho: f64, lid: Option<f64>, sky: Option<f64>) -> Scene {
    let mut d = SceneDesc { name: "open-box".into(), ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("floor", Rgb::splat(0.5)));
    d.materials.push(MaterialDesc::diffuse("wall", Rgb::splat(wall_rho)));
    d.materials.push(MaterialDesc { emission: Rgb::splat(lid.unwrap_or(0.0)), ..MaterialDesc::diffuse("lid", Rgb::ZERO) });
    let faces = common::box_faces(DVec3::ZERO, DVec3::new(1.0, h, 1.0), true);
    // box_faces order: z = lo, z = hi, y = lo, y = hi, x = hi, x = lo.
    let names = ["wall-z0", "wall-z1", "floor", "lid", "wall-x1", "wall-x0"];
    for (k, (f, name)) in faces.into_iter().zip(names).enumerate() {
        let material = match name {
            "floor" => 0,
            "lid" if lid.is_none() => continue,
            "lid" => 2,
            _ => 1,
        };
        d.objects.push(ObjectDesc { name: name.into(), loc: None });
        let object = d.objects.len() as u32 - 1;
        let _ = k;
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: f, material, object, loc: None });
    }
    d.sky = sky.map(|l| Sky::uniform(Rgb::splat(l)));
    Scene::from_desc(d).unwrap()
}

/// The open box's opening (the unit square at y = 1) and the portal layouts the portal
/// tests try: none, the opening itself, half of it, a larger one higher up (part of it
/// hidden by the walls), and two that overlap as seen from the floor (their shared sky
/// counts once).
fn portal_variants() -> (Vec<DVec3>, [(&'static str, Vec<Vec<DVec3>>); 5]) {
    let sq = |x0: f64, x1: f64, y: f64, z0: f64, z1: f64| vec![DVec3::new(x0, y, z0), DVec3::new(x1, y, z0), DVec3::new(x1, y, z1), DVec3::new(x0, y, z1)];
    let opening = sq(0.0, 1.0, 1.0, 0.0, 1.0);
    let variants = [
        ("no portal", vec![]),
        ("the opening", vec![opening.clone()]),
        ("half the opening", vec![sq(0.0, 0.5, 1.0, 0.0, 1.0)]),
        ("larger, higher", vec![sq(-0.5, 1.5, 1.3, -0.5, 1.5)]),
        ("the opening and half of it higher up", vec![opening.clone(), sq(0.0, 0.5, 1.2, 0.0, 1.0)]),
    ];
    (opening, variants)
}

fn object_radiance(solved: &Solved, name: &str) -> f64 {
    let o = solved.objects().into_iter().find(|o| o.name == name).unwrap_or_else(|| panic!("no object {name}"));
    o.radiance_rgb[0]
}

fn settings(transport: Kind, method: form_factor::Method, solver: Solver) -> Settings {
    let mut s = Settings { mesh_size: Some(0.05), transport, solver, ..Default::default() };
    s.form_factors.method = method;
    s
}

#[test]
fn floor_of_an_open_box_with_black_walls_sees_the_sky_through_the_opening() {
    let h = 0.5;
    let exact = 0.5 * 2.0 * parallel_squares(1.0, h);
    for (transport, solver) in
        [(Kind::Rows, Solver::Jacobi), (Kind::Hierarchical, Solver::Jacobi), (Kind::Rows, Solver::StochasticJacobi)]
    {
        let scene = open_box(h, 0.0, None, Some(2.0));
        let solved = solve_scene(scene, &settings(transport, form_factor::Method::PointSampled, solver), &NoProgress).unwrap();
        let l = object_radiance(&solved, "floor");
        let err = (l - exact) / exact;
        eprintln!("{transport:?} {solver}: floor L = {l:.5}, exact ρ·L·F = {exact:.5} ({:+.3} %)", 100.0 * err);
        assert!(err.abs() < 0.01, "{transport:?} {solver}: floor {l} against {exact}");
        // A black wall reflects nothing; the sky alone would be 2·0 = 0.
        assert!(object_radiance(&solved, "wall-x0").abs() < 1e-12);
    }
}

#[test]
fn open_box_under_the_sky_matches_the_box_closed_by_a_black_emitting_lid() {
    let h = 0.6;
    for (transport, method, tol) in [
        (Kind::Rows, form_factor::Method::Analytic, 0.01),
        (Kind::Rows, form_factor::Method::PointSampled, 0.01),
        (Kind::Hierarchical, form_factor::Method::PointSampled, 0.02),
    ] {
        let s = settings(transport, method, Solver::Jacobi);
        let sky = solve_scene(open_box(h, 0.7, None, Some(1.0)), &s, &NoProgress).unwrap();
        let lid = solve_scene(open_box(h, 0.7, Some(1.0), None), &s, &NoProgress).unwrap();
        for name in ["floor", "wall-x0", "wall-x1", "wall-z0", "wall-z1"] {
            let (a, b) = (object_radiance(&sky, name), object_radiance(&lid, name));
            let err = (a - b) / b;
            eprintln!("{transport:?} {}: {name} sky {a:.5} lid {b:.5} ({:+.3} %)", method.name(), 100.0 * err);
            assert!(err.abs() < tol, "{transport:?} {}: {name}: sky {a} against lid {b}", method.name());
        }
        // The sky's first reflection is the emitted power of the system: ρ·π·L·S·A summed.
        let e = sky.solution.energy.emitted[0];
        let expect: f64 = sky
            .mesh
            .elements
            .iter()
            .zip(&sky.external_irradiance)
            .zip(&sky.receivers.open_fraction)
            .map(|((el, h), f)| {
                let rho = sky.scene.materials[sky.scene.polygons[el.patch as usize].material as usize].reflectance.x;
                rho * h.x * el.area * f
            })
            .sum();
        assert!((e - expect).abs() <= 1e-9 * expect, "emitted {e} against the sky's first reflection {expect}");
    }
}

#[test]
fn no_sky_light_enters_a_closed_room() {
    let mut d = SceneDesc { name: "closed".into(), ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    d.objects.push(ObjectDesc { name: "room".into(), loc: None });
    for f in common::box_faces(DVec3::ZERO, DVec3::ONE, true) {
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: f, material: 0, object: 0, loc: None });
    }
    // A box inside, two-sided, so rays also start from surfaces facing every way.
    d.objects.push(ObjectDesc { name: "box".into(), loc: None });
    d.materials.push(MaterialDesc { two_sided: Some(true), ..MaterialDesc::diffuse("box", Rgb::splat(0.5)) });
    for f in common::box_faces(DVec3::splat(0.3), DVec3::splat(0.6), false) {
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: f, material: 1, object: 1, loc: None });
    }
    d.sky = Some(Sky::uniform(Rgb::ONE));
    let scene = Scene::from_desc(d).unwrap();
    scene.check_emits().expect("a sky is a light");
    let solved = solve_scene(scene, &Settings { mesh_size: Some(0.1), ..Default::default() }, &NoProgress).unwrap();
    assert!(solved.external_irradiance.iter().all(|&h| h == Rgb::ZERO), "sky light inside a closed room");
    assert!(solved.solution.radiosity.iter().all(|b| *b == Rgb::ZERO));
}

#[test]
fn final_gather_shows_the_sky_and_a_plate_lit_by_it_exactly() {
    let l_sky = 1.5;
    let mut d = SceneDesc { name: "plate".into(), ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    d.objects.push(ObjectDesc { name: "plate".into(), loc: None });
    let v = vec![DVec3::new(0., 0., 0.), DVec3::new(0., 0., 1.), DVec3::new(1., 0., 1.), DVec3::new(1., 0., 0.)];
    d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v, material: 0, object: 0, loc: None });
    d.sky = Some(Sky::uniform(Rgb::splat(l_sky)));
    let scene = Scene::from_desc(d).unwrap();
    let solved = solve_scene(scene, &Settings { mesh_size: Some(0.1), ..Default::default() }, &NoProgress).unwrap();
    assert!(solved.external_irradiance.iter().all(|&h| h == Rgb::splat(PI * l_sky)));
    // The plate fills the middle of the view; the corners see only sky.
    let cam = Camera { position: DVec3::new(0.5, 1.0, 0.5), look_at: DVec3::new(0.5, 0.0, 0.5), up: DVec3::Z, vfov_deg: 90.0 };
    let two: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
    let tracer = ElementTracer::new(&solved.mesh, &two);
    let (w, hgt) = (32, 32);
    let check = |img: &radiosity::render::Image, what: &str| {
        let (mut sky_px, mut plate_px) = (0, 0);
        for (k, p) in img.pixels.iter().enumerate() {
            let (x, y) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
            // Pixel centre direction: the plate spans x, y in [8, 24) of the 32² image at 90°.
            let inside = (8.5..23.5).contains(&x) && (8.5..23.5).contains(&y);
            let outside = !(7.0..25.0).contains(&x) || !(7.0..25.0).contains(&y);
            if inside {
                plate_px += 1;
                assert!((p.x - 0.5 * l_sky).abs() < 1e-9, "{what}: plate pixel {x},{y} = {}", p.x);
            } else if outside {
                sky_px += 1;
                assert!((p.x - l_sky).abs() < 1e-9, "{what}: sky pixel {x},{y} = {}", p.x);
            }
        }
        assert!(sky_px > 300 && plate_px > 200, "{what}: {sky_px} sky and {plate_px} plate pixels");
    };
    for (gathered, axis) in [(true, 2), (false, 0)] {
        let opts = radiosity::render::gather::Options { width: w, height: hgt, spp_axis: 2, shadow_axis: 2, gather_axis: axis, seed: 1, noise: 0.0 };
        let indirect = solved.indirect(gathered);
        let (img, _) = solved.render_gather(&cam, &opts, &tracer, &indirect, &NoProgress);
        check(&img, if gathered { "gathered" } else { "interpolated" });
    }
    let opts = radiosity::render::gouraud::Options {
        width: w,
        height: hgt,
        spp_axis: 1,
        shading: radiosity::render::gouraud::Shading::Gouraud,
    };
    check(&solved.render(&cam, &opts, &tracer, &NoProgress), "gouraud");
}

/// A closed two-sided room under the sky (walls 0.05 thick, a table inside) with the
/// hierarchical operator at a minimum node size (0.4) where one cluster holds both sides of
/// a wall: the largest radiosity inside against the largest outside. `LEAKDBG=1` prints the
/// links of the brightest inside element, ancestor by ancestor.
fn closed_two_sided_room_leak(cluster_receivers: bool) -> (f64, f64, usize) {
    let mut d = SceneDesc { name: "closed-two-sided".into(), two_sided: true, ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    d.objects.push(ObjectDesc { name: "room".into(), loc: None });
    // The outer shell faces out, the inner one faces in.
    for (lo, hi, inward) in [(DVec3::splat(-0.05), DVec3::splat(1.05), false), (DVec3::ZERO, DVec3::ONE, true)] {
        for f in common::box_faces(lo, hi, inward) {
            d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: f, material: 0, object: 0, loc: None });
        }
    }
    d.objects.push(ObjectDesc { name: "table".into(), loc: None });
    for f in common::box_faces(DVec3::new(0.3, 0.0, 0.3), DVec3::new(0.7, 0.4, 0.7), false) {
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: f, material: 0, object: 1, loc: None });
    }
    d.sky = Some(Sky::uniform(Rgb::ONE));
    let scene = Scene::from_desc(d).unwrap();
    let mut s = settings(Kind::Hierarchical, form_factor::Method::PointSampled, Solver::Jacobi);
    s.links.min_size = Some(0.4);
    s.links.cluster_receivers = cluster_receivers;
    let solved = solve_scene(scene, &s, &NoProgress).unwrap();
    let b = solved.solution.display_radiosity();
    let (mut inside, mut outside, mut n_in) = (0.0f64, 0.0f64, 0);
    for (i, e) in solved.mesh.elements.iter().enumerate() {
        let c = e.centroid;
        // Inside: the inner shell's faces (facing the room's centre) and the table.
        let in_room = c.min_element() > -1e-9 && c.max_element() < 1.0 + 1e-9;
        let table = c.y < 0.41 && (0.29..0.71).contains(&c.x) && (0.29..0.71).contains(&c.z);
        if in_room && (e.normal.dot(DVec3::splat(0.5) - c) > 0.0 || table) {
            inside = inside.max(b[i].x);
            n_in += 1;
        } else {
            outside = outside.max(b[i].x);
        }
    }
    eprintln!("cluster receivers {cluster_receivers}: {n_in} elements inside, max B {inside:e}; outside max B {outside}");
    if std::env::var_os("LEAKDBG").is_some() && inside > 0.0 {
        // The worst inside element's links, ancestor by ancestor.
        let h = solved.transport.as_ref().unwrap().hierarchy().unwrap();
        let tree = &h.tree;
        let (wi, _) = b.iter().enumerate().filter(|(i, _)| {
            let c = solved.mesh.elements[*i].centroid;
            c.min_element() > -1e-9 && c.max_element() < 1.0 + 1e-9 && solved.mesh.elements[*i].normal.dot(DVec3::splat(0.5) - c) > 0.0
        }).max_by(|a, b| a.1.x.total_cmp(&b.1.x)).unwrap();
        let leaf = tree.leaf_of[wi];
        eprintln!("worst inside element {wi} at {:?} normal {:?} B {}", solved.mesh.elements[wi].centroid, solved.mesh.elements[wi].normal, b[wi].x);
        let mut k = 0u32;
        loop {
            let nd = &tree.nodes[k as usize];
            for (src, f, g, dir) in h.links_full(k) {
                let ns = &tree.nodes[src as usize];
                let (mut sum, mut a) = (0.0, 0.0);
                for slot in ns.first..ns.first + ns.count {
                    let j = tree.order[slot as usize] as usize;
                    sum += b[j].x * solved.mesh.elements[j].area;
                    a += solved.mesh.elements[j].area;
                }
                eprintln!(
                    "  recv node {k} (surface {}, count {}, lo {:?} hi {:?}) <- src {src} (surface {}, count {}, lo {:?} hi {:?}) f {f:.4} g {g:?} dir {dir:?} mean B {:.4}",
                    nd.surface, nd.count, nd.lo, nd.hi, ns.surface, ns.count, ns.lo, ns.hi, sum / a.max(1e-30)
                );
            }
            if k == leaf {
                break;
            }
            k = *nd.child.iter().find(|&&c| tree.contains(c, leaf)).unwrap();
        }
    }
    (inside, outside, n_in)
}

/// No sky light leaks through two-sided walls into a closed room with the hierarchical
/// operator, whether only surfaces receive links or clusters too (the default): exactly
/// zero inside. Cluster receivers once took a wall slab's first-order directional reading,
/// which mixes its lit outside with its dark inside (max B 5.6e-2 inside against 1.58).
#[test]
fn sky_light_does_not_leak_through_two_sided_walls_into_a_closed_room() {
    for cluster_receivers in [false, true] {
        let (inside, outside, n_in) = closed_two_sided_room_leak(cluster_receivers);
        assert!(outside > 1.0, "the outside is sky-lit");
        assert!(n_in > 100 && inside == 0.0, "cluster receivers {cluster_receivers}: sky light inside, B up to {inside:e}");
    }
}

fn sun_scene(direction: DVec3, with_roof: bool) -> Scene {
    let mut d = SceneDesc { name: "sun".into(), ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    d.objects.push(ObjectDesc { name: "floor".into(), loc: None });
    let floor = vec![DVec3::new(0., 0., 0.), DVec3::new(0., 0., 2.), DVec3::new(2., 0., 2.), DVec3::new(2., 0., 0.)];
    d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: floor, material: 0, object: 0, loc: None });
    if with_roof {
        // A one-sided square 0.5 on a side at height 1 over the floor's centre, facing up.
        d.objects.push(ObjectDesc { name: "roof".into(), loc: None });
        let roof =
            vec![DVec3::new(0.75, 1., 0.75), DVec3::new(0.75, 1., 1.25), DVec3::new(1.25, 1., 1.25), DVec3::new(1.25, 1., 0.75)];
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: roof, material: 0, object: 1, loc: None });
    }
    let sun = radiosity::scene::Sun { direction, irradiance: Rgb::splat(100.0), angular_diameter_deg: 0.53 };
    d.sky = Some(Sky { radiance: Rgb::ZERO, sun: Some(sun), environment: None, portals: Vec::new() });
    Scene::from_desc(d).unwrap()
}

/// A floor under a sun 60° from the zenith: irradiance E·cos 60°, so L = ρ·E·cos θ/π on
/// every element, and the sun's power on the floor is E·cos θ·A.
#[test]
fn sun_lights_an_open_floor_by_the_cosine_law() {
    let t = 60f64.to_radians();
    let scene = sun_scene(DVec3::new(t.sin(), t.cos(), 0.0), false);
    let solved = solve_scene(scene, &Settings { mesh_size: Some(0.2), ..Default::default() }, &NoProgress).unwrap();
    // The disk's mean cosine is cos θ·(1 + cos r)/2; its 8 × 8 directions per element sample
    // the ±r·tan θ = ±0.8 % spread across it.
    let cos_r = solved.scene.sky.as_ref().unwrap().sun.unwrap().cos_radius();
    let exact = 0.5 * 100.0 * t.cos() * 0.5 * (1.0 + cos_r) / PI;
    for b in solved.solution.display_radiosity() {
        assert!((b.x / PI - exact).abs() < 1e-3 * exact, "L {} against {exact}", b.x / PI);
    }
    let incident = solved.energy().external_incident.unwrap()[0];
    assert!((incident - 100.0 * t.cos() * 4.0).abs() < 1e-3 * incident, "sun power on the floor {incident}");
}

/// A roof over the floor with the sun overhead: the floor is dark in its shadow and fully
/// lit outside it, element by element and point by point (the final gather's estimate).
#[test]
fn sun_casts_a_sharp_shadow() {
    let solved = solve_scene(sun_scene(DVec3::Y, true), &Settings { mesh_size: Some(0.05), ..Default::default() }, &NoProgress)
        .unwrap();
    let b = solved.solution.display_radiosity();
    // Overhead, the disk's mean cosine is (1 + cos r)/2.
    let lit_b = 0.5 * 100.0 * 0.5 * (1.0 + solved.scene.sky.as_ref().unwrap().sun.unwrap().cos_radius());
    let (mut shadow, mut lit) = (0, 0);
    for (i, e) in solved.mesh.elements.iter().enumerate() {
        if e.normal.y < 0.5 || e.centroid.y > 0.5 {
            continue; // the roof
        }
        let (dx, dz) = ((e.centroid.x - 1.0).abs(), (e.centroid.z - 1.0).abs());
        if dx < 0.2 && dz < 0.2 {
            shadow += 1;
            assert_eq!(b[i].x, 0.0, "element at {:?} in the shadow", e.centroid);
        } else if dx > 0.3 || dz > 0.3 {
            lit += 1;
            assert!((b[i].x - lit_b).abs() < 1e-6 * lit_b, "element at {:?}: B {} against {lit_b}", e.centroid, b[i].x);
        }
    }
    assert!(shadow > 40 && lit > 1000, "{shadow} shadowed, {lit} lit elements");
    let sun = solved.scene.sky.as_ref().unwrap().sun.unwrap();
    let pts: Vec<(f64, f64)> = (0..16).map(|k| ((k % 4) as f64 / 4.0 + 0.1, (k / 4) as f64 / 4.0 + 0.1)).collect();
    let floor = solved.mesh.elements.iter().find(|e| e.normal.y > 0.5 && e.centroid.y < 0.5).unwrap().patch;
    for (x, expect) in [(1.0, 0.0), (1.2, 0.0), (1.3, 1.0), (0.2, 1.0)] {
        let (f, _) = radiosity::sky::sun_factor_at(&solved.rays, &sun, DVec3::new(x, 0.0, 1.0), DVec3::Y, floor, &pts);
        assert!((f - expect).abs() < 1e-5, "sun factor at x = {x}: {f}");
    }
}

/// The final gather under a sun: every visible floor point shows ρ·E·cos θ/π (the shadow
/// rays all reach the disk), and a camera looking into the disk sees its radiance E/Ω.
#[test]
fn final_gather_shows_the_sunlit_floor_and_the_sun() {
    let t = 30f64.to_radians();
    let dir = DVec3::new(t.sin(), t.cos(), 0.0);
    let solved = solve_scene(sun_scene(dir, false), &Settings { mesh_size: Some(0.2), ..Default::default() }, &NoProgress).unwrap();
    let sun = solved.scene.sky.as_ref().unwrap().sun.unwrap();
    let two: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
    let tracer = ElementTracer::new(&solved.mesh, &two);
    let opts = radiosity::render::gather::Options { width: 16, height: 16, spp_axis: 2, shadow_axis: 2, gather_axis: 2, seed: 5, noise: 0.0 };
    let exact = 0.5 * 100.0 * t.cos() * 0.5 * (1.0 + sun.cos_radius()) / PI;
    let down = Camera { position: DVec3::new(1.0, 1.0, 1.0), look_at: DVec3::new(1.0, 0.0, 1.0), up: DVec3::Z, vfov_deg: 60.0 };
    let indirect = solved.indirect(true);
    let (img, _) = solved.render_gather(&down, &opts, &tracer, &indirect, &NoProgress);
    for p in &img.pixels {
        assert!((p.x - exact).abs() < 2e-3 * exact, "floor pixel {} against {exact}", p.x);
    }
    // Into the disk (0.53°) with a 0.2° field of view: every pixel is the sun.
    let up = Camera { position: DVec3::new(1.0, 0.5, 1.0), look_at: DVec3::new(1.0, 0.5, 1.0) + dir, up: DVec3::Z, vfov_deg: 0.2 };
    let (img, _) = solved.render_gather(&up, &opts, &tracer, &indirect, &NoProgress);
    let l = sun.radiance().x;
    assert!(img.pixels.iter().all(|p| (p.x - l).abs() < 1e-9 * l), "sun pixels {} against {l}", img.pixels[0].x);
}

/// An equirectangular environment whose texel at direction d is `texel(d)`, `w × h`.
fn environment(w: usize, h: usize, texel: impl Fn(DVec3) -> [f32; 3], rotation_deg: f64) -> radiosity::scene::Environment {
    let mut t = Vec::with_capacity(w * h);
    for j in 0..h {
        for k in 0..w {
            let (u, v) = ((k as f64 + 0.5) / w as f64, (j as f64 + 0.5) / h as f64);
            let (phi, elev) = ((u - 0.5) * 2.0 * PI, (0.5 - v) * PI);
            t.push(texel(DVec3::new(elev.cos() * phi.cos(), elev.sin(), elev.cos() * phi.sin())));
        }
    }
    let texture = radiosity::scene::Texture::from_linear("env", w, h, t).unwrap();
    radiosity::scene::Environment { texture: std::sync::Arc::new(texture), strength: 1.0, rotation_deg }
}

/// The documented mapping: every texel centre's direction reads that texel exactly, and a
/// rotation of 90° shows what the image holds at +X towards −Z.
#[test]
fn environment_directions_follow_the_equirectangular_convention() {
    let (w, h) = (8, 4);
    let id = |d: DVec3| {
        let u = d.z.atan2(d.x) / (2.0 * PI) + 0.5;
        let v = 0.5 - d.y.asin() / PI;
        let (k, j) = ((u * w as f64).floor() as usize % w, (v * h as f64).floor() as usize);
        [(j * w + k) as f32, 0.0, 0.0]
    };
    let env = environment(w, h, id, 0.0);
    let turned = environment(w, h, id, 90.0);
    for j in 0..h {
        for k in 0..w {
            let (u, v) = ((k as f64 + 0.5) / w as f64, (j as f64 + 0.5) / h as f64);
            let (phi, elev) = ((u - 0.5) * 2.0 * PI, (0.5 - v) * PI);
            let d = DVec3::new(elev.cos() * phi.cos(), elev.sin(), elev.cos() * phi.sin());
            let want = (j * w + k) as f64;
            assert!((env.radiance(d, 0.0).x - want).abs() < 1e-5, "texel ({k}, {j}): {}", env.radiance(d, 0.0));
            // R_y(90°): (x, y, z) -> (z, y, -x).
            let r = DVec3::new(d.z, d.y, -d.x);
            assert!((turned.radiance(r, 0.0).x - want).abs() < 1e-5, "turned texel ({k}, {j})");
        }
    }
    // +X is the middle of the image (u = 1/2), the zenith its top row.
    let mid = environment(8, 4, |d| [if d.x > 0.7 { 1.0 } else { 0.0 }, (1.0 + d.y) as f32, 0.0], 0.0);
    assert!(mid.radiance(DVec3::X, 0.0).x > 0.0 && mid.radiance(DVec3::NEG_X, 0.0).x == 0.0);
    assert!(mid.radiance(DVec3::Y, 0.0).y > 1.9 && mid.radiance(DVec3::NEG_Y, 0.0).y < 0.1);
}

/// Closed forms under an environment image L(d) = a + b·d_y (red) and c (green): a plate
/// facing up receives π·a + 2π·b/3, one facing +X receives π·a (the d_y term cancels), and
/// the constant channel π·c on both; the final reflection is ρ·E/π. Camera rays that leave
/// the scene straight up see a + b.
#[test]
fn environment_image_lights_surfaces_by_direction() {
    let (a, b, c, rho) = (1.0, 0.8, 0.5, 0.5);
    let mut d = SceneDesc { name: "env".into(), ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(rho)));
    let plates = [
        ("up", vec![DVec3::new(0., 0., 0.), DVec3::new(0., 0., 1.), DVec3::new(1., 0., 1.), DVec3::new(1., 0., 0.)]),
        // Facing +X, far below the first plate's plane and beside it: they cannot see each other.
        ("side", vec![DVec3::new(10., -5., 0.), DVec3::new(10., -4., 0.), DVec3::new(10., -4., 1.), DVec3::new(10., -5., 1.)]),
    ];
    for (k, (name, v)) in plates.into_iter().enumerate() {
        d.objects.push(ObjectDesc { name: name.into(), loc: None });
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v, material: 0, object: k as u32, loc: None });
    }
    let env = environment(512, 256, |dir| [(a + b * dir.y) as f32, c as f32, 0.0], 37.0);
    d.sky = Some(Sky { radiance: Rgb::ZERO, sun: None, environment: Some(env), portals: Vec::new() });
    let scene = Scene::from_desc(d).unwrap();
    let s = Settings { mesh_size: Some(0.25), ..Default::default() };
    let solved = solve_scene(scene, &s, &NoProgress).unwrap();
    let obj = |name: &str| Rgb::from_array(solved.objects().into_iter().find(|o| o.name == name).unwrap().radiance_rgb);
    let (up, side) = (obj("up"), obj("side"));
    let want_up = Rgb::new(rho * (a + 2.0 * b / 3.0), rho * c, 0.0);
    let want_side = Rgb::new(rho * a, rho * c, 0.0);
    eprintln!("up {up} (want {want_up}), side {side} (want {want_side})");
    for (got, want) in [(up, want_up), (side, want_side)] {
        for ch in 0..2 {
            assert!((got[ch] - want[ch]).abs() <= 5e-3 * want[ch], "{got} against {want}");
        }
    }
    // Straight up, a 10° view: every pixel shows a + b·d_y with d_y ≥ cos 7.1°.
    let cam = Camera { position: DVec3::new(0.5, 1.0, 0.5), look_at: DVec3::new(0.5, 2.0, 0.5), up: DVec3::Z, vfov_deg: 10.0 };
    let two: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
    let tracer = ElementTracer::new(&solved.mesh, &two);
    let gouraud = radiosity::render::gouraud::Options { width: 16, height: 16, spp_axis: 2, shading: radiosity::render::gouraud::Shading::Gouraud };
    let opts = radiosity::render::gather::Options { width: 16, height: 16, spp_axis: 2, shadow_axis: 2, gather_axis: 2, seed: 1, noise: 0.0 };
    let (gathered, _) = solved.render_gather(&cam, &opts, &tracer, &solved.indirect(true), &NoProgress);
    for img in [solved.render(&cam, &gouraud, &tracer, &NoProgress), gathered] {
        for p in &img.pixels {
            assert!(p.x > a + b * 0.99 && p.x < a + b + 1e-6 && (p.y - c).abs() < 1e-6, "sky pixel {p}");
        }
    }
}

/// `[sky] image = "FILE"` in TOML: an EXR (written by our own encoder) and a Radiance
/// .hdr read as linear radiance, `strength` and `rotation` applied; clear errors for a
/// radiance given with it, a negative strength, a missing file and a NaN texel.
#[test]
fn environment_files_load_from_toml_with_clear_errors() {
    let dir = std::env::temp_dir().join(format!("radiosity-env-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // 4 × 2: the top row 3.0, the bottom row 0.25 (red), green 1.5 everywhere.
    let mut img = radiosity::render::Image::new(4, 2);
    for (k, p) in img.pixels.iter_mut().enumerate() {
        *p = Rgb::new(if k < 4 { 3.0 } else { 0.25 }, 1.5, 0.0);
    }
    std::fs::write(dir.join("env.exr"), radiosity::output::exr::encode(&img).unwrap()).unwrap();
    let mut hdr = Vec::new();
    let px: Vec<image::Rgb<f32>> = img.pixels.iter().map(|p| image::Rgb([p.x as f32, p.y as f32, p.z as f32])).collect();
    image::codecs::hdr::HdrEncoder::new(&mut hdr).encode(&px, 4, 2).unwrap();
    std::fs::write(dir.join("env.hdr"), hdr).unwrap();
    for file in ["env.exr", "env.hdr"] {
        let toml = format!("mesh = \"builtin:cornell\"\n[sky]\nimage = \"{file}\"\nstrength = 2.0\nrotation = 45\n");
        std::fs::write(dir.join("s.toml"), toml).unwrap();
        let desc = radiosity::scene::load(dir.join("s.toml").to_str().unwrap()).unwrap();
        let env = desc.sky.as_ref().unwrap().environment.as_ref().unwrap();
        assert_eq!((env.strength, env.rotation_deg), (2.0, 45.0));
        let (up, down) = (env.radiance(DVec3::Y, 0.0), env.radiance(DVec3::NEG_Y, 0.0));
        // Radiance HDR keeps 8-bit mantissas: 1 % there.
        let tol = if file.ends_with("hdr") { 1e-2 } else { 1e-6 };
        assert!((up - Rgb::new(6.0, 3.0, 0.0)).abs().max_element() <= tol * 6.0, "{file}: up {up}");
        assert!((down - Rgb::new(0.5, 3.0, 0.0)).abs().max_element() <= tol * 3.0, "{file}: down {down}");
    }
    let bad = |body: &str, want: &str| {
        std::fs::write(dir.join("b.toml"), format!("mesh = \"builtin:cornell\"\n[sky]\n{body}\n")).unwrap();
        let e = radiosity::scene::load(dir.join("b.toml").to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains(want) && e.contains("b.toml"), "{body}: {e}");
    };
    bad("image = \"env.exr\"\nradiance = 1", "not both");
    bad("image = \"env.exr\"\nstrength = -1", "strength -1");
    bad("image = \"missing.exr\"", "missing.exr");
    bad("radiance = 1\nrotation = 10", "belong to an image");
    img.pixels[5] = Rgb::new(f64::NAN, 0.0, 0.0);
    std::fs::write(dir.join("nan.exr"), radiosity::output::exr::encode(&img).unwrap()).unwrap();
    bad("image = \"nan.exr\"", "texel (1, 1)");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Sky portals change the noise, not the light. The floor of an open unit box with black
/// walls sees only the sky through the opening: `L = ρ·L_sky·F(x → opening)`, exactly (the
/// contour integral per pixel centre). Rendered without a portal (cosine gather rays find the
/// sky), with the opening as the portal, with a portal over half of it (the other half left
/// to the rays), with a larger one higher up (part of it hidden by the walls) and with two
/// that overlap as seen from the floor: every image
/// matches the closed form on average (within its noise), and the exact portal cuts the
/// pixels' error to a fraction of the rays' alone.
#[test]
fn sky_portals_keep_the_light_and_cut_the_noise() {
    let (opening, variants) = portal_variants();
    let (w, h) = (24, 24);
    let cam = Camera { position: DVec3::new(0.5, 0.95, 0.5), look_at: DVec3::new(0.5, 0.0, 0.5), up: DVec3::Z, vfov_deg: 60.0 };
    let pin = radiosity::render::PinholeCamera::new(&cam, w, h);
    let mut rms = Vec::new();
    for (name, portals) in variants {
        let mut scene = open_box(1.0, 0.0, None, Some(1.0));
        scene.sky.as_mut().unwrap().portals = portals.into_iter().map(|v| radiosity::scene::Portal::new(v).unwrap()).collect();
        let solved = solve_scene(scene, &Settings { mesh_size: Some(0.1), ..Default::default() }, &NoProgress).unwrap();
        let two: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
        let tracer = ElementTracer::new(&solved.mesh, &two);
        let opts = radiosity::render::gather::Options { width: w, height: h, spp_axis: 4, shadow_axis: 2, gather_axis: 2, seed: 1, noise: 0.0 };
        let (img, _) = solved.render_gather(&cam, &opts, &tracer, &solved.indirect(true), &NoProgress);
        let (mut ratio, mut err2, mut n) = (0.0, 0.0, 0);
        for (k, px) in img.pixels.iter().enumerate() {
            let d = pin.direction((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
            let p = cam.position + d * (-cam.position.y / d.y);
            if (p.x - 0.5).abs() > 0.45 || (p.z - 0.5).abs() > 0.45 {
                continue;
            }
            let exact = 0.5 * radiosity::form_factor::analytic::point_factor(p, DVec3::Y, &opening, -DVec3::Y);
            ratio += px.x / exact;
            err2 += (px.x / exact - 1.0).powi(2);
            n += 1;
        }
        let (mean, r) = (ratio / n as f64, (err2 / n as f64).sqrt());
        eprintln!("{name}: {n} floor pixels, mean ratio to the closed form {mean:.4}, RMS relative error {:.2} %", 100.0 * r);
        assert!(n > 300, "{name}: {n} floor pixels");
        // Within four standard errors of the pixels' mean (and the closed form's value at
        // the pixel centre against its mean over the pixel, 0.3 %).
        let tol = 4.0 * r / (n as f64).sqrt() + 3e-3;
        assert!((mean - 1.0).abs() < tol, "{name}: mean ratio {mean}, tolerance {tol}");
        rms.push(r);
    }
    assert!(rms[1] < 0.25 * rms[0], "the opening as a portal: RMS {:.4} against {:.4} without", rms[1], rms[0]);
}

/// The element exposure (the sky's first reflection in the solve) through portals: the
/// floor of an open box with black walls sees the sky through the opening only, so each
/// floor element's exposure is the mean over it of the point-to-opening factor. Through a
/// portal on the opening the element's mean is unbiased and its noise far lower at fewer
/// rays; portals over part of the opening, beside it or overlapping keep it unbiased.
#[test]
fn element_exposure_through_portals_matches_the_opening() {
    use radiosity::accel::SceneRays;
    use radiosity::mesh::Receivers;
    let (opening, variants) = portal_variants();
    let scene = open_box(1.0, 0.0, None, Some(1.0));
    let mesh = radiosity::mesh::mesh_uniform(&scene, 0.1);
    let rays = SceneRays::new(&scene.polygons);
    let rec = Receivers::compute(&scene, &mesh, &rays);
    // Floor elements and their exact exposure (a 6 × 6 grid of point factors over each).
    let floor: Vec<(usize, f64)> = (0..mesh.len())
        .filter(|&e| mesh.elements[e].normal.y > 0.99 && mesh.elements[e].centroid.y.abs() < 1e-9)
        .map(|e| {
            let el = &mesh.elements[e];
            let k = 6;
            let mut f = 0.0;
            for i in 0..k {
                for j in 0..k {
                    let p = el.point(&mesh.positions, (i as f64 + 0.5) / k as f64, (j as f64 + 0.5) / k as f64);
                    f += radiosity::form_factor::analytic::point_factor(p, DVec3::Y, &opening, -DVec3::Y);
                }
            }
            (e, f / (k * k) as f64)
        })
        .collect();
    assert_eq!(floor.len(), 100);
    let mut rms = Vec::new();
    for (name, portals) in variants {
        let portals: Vec<_> = portals.into_iter().map(|v| radiosity::scene::Portal::new(v).unwrap()).collect();
        let (s, cast) = radiosity::sky::exposure(&mesh, &rays, &rec, 8, &portals, &NoProgress);
        let (mut ratio, mut err2) = (0.0, 0.0);
        for &(e, exact) in &floor {
            ratio += s[e] / exact;
            err2 += (s[e] / exact - 1.0).powi(2);
        }
        let n = floor.len() as f64;
        let (mean, r) = (ratio / n, (err2 / n).sqrt());
        eprintln!("{name}: {cast} rays, floor exposure / exact: mean {mean:.4}, RMS {:.2} %", 100.0 * r);
        let tol = 4.0 * r / n.sqrt() + 2e-3;
        assert!((mean - 1.0).abs() < tol, "{name}: mean ratio {mean}, tolerance {tol}");
        rms.push((r, cast));
    }
    assert!(rms[1].0 < 0.25 * rms[0].0 && rms[1].1 < rms[0].1, "the opening as a portal: RMS {:?} against {:?} without", rms[1], rms[0]);
}

/// Sponza's element exposure with and without its portal against many rays:
/// `SPONZA_SKY=scenes/sponza-sky.toml cargo test --release -p radiosity --test sky
/// exposure_noise_under_portals -- --ignored --nocapture`.
#[test]
#[ignore]
fn exposure_noise_under_portals() {
    use radiosity::accel::SceneRays;
    use radiosity::mesh::Receivers;
    let Ok(path) = std::env::var("SPONZA_SKY") else { return };
    let scene = radiosity::scene::load_scene(&path).unwrap();
    let size = radiosity::mesh::default_size(&scene);
    let mesh = radiosity::mesh::mesh_uniform(&scene, size);
    let rays = SceneRays::new(&scene.polygons);
    let rec = Receivers::compute(&scene, &mesh, &rays);
    let portals = scene.sky.as_ref().unwrap().portals.clone();
    let t = std::time::Instant::now();
    let (truth, _) = radiosity::sky::exposure(&mesh, &rays, &rec, 32, &[], &NoProgress);
    eprintln!("truth {:.1} s", t.elapsed().as_secs_f64());
    let area: Vec<f64> = mesh.elements.iter().map(|e| e.area).collect();
    for (name, axis, ps) in [("cosine 8", 8, &[][..]), ("portal 8", 8, &portals[..]), ("cosine 4", 4, &[][..]), ("portal 12", 12, &portals[..])] {
        let t = std::time::Instant::now();
        let (s, n) = radiosity::sky::exposure(&mesh, &rays, &rec, axis, ps, &NoProgress);
        let secs = t.elapsed().as_secs_f64();
        let (mut e2, mut a, mut bias, mut lit) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..s.len() {
            e2 += area[i] * (s[i] - truth[i]).powi(2);
            bias += area[i] * (s[i] - truth[i]);
            lit += area[i] * truth[i];
            a += area[i];
        }
        eprintln!("{name}: {secs:.2} s, {n} rays, RMS {:.5}, mean {:.5} (truth {:.5}), bias {:.2e}", (e2 / a).sqrt(), (lit + bias) / a, lit / a, bias / a);
    }
}
