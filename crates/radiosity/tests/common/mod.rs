//! Helpers shared by the integration tests.
#![allow(dead_code)]

use glam::DVec3;
use radiosity::scene::{MaterialDesc, ObjectDesc, PolygonDesc, Scene, SceneDesc};
use radiosity::Rgb;

/// A scene of named quads (each its own object), grey ρ = 0.5, no emission.
pub fn quads(quads: &[(&str, [DVec3; 4])]) -> Scene {
    let mut d = SceneDesc { name: "test".into(), ..Default::default() };
    d.materials.push(MaterialDesc::diffuse("grey", Rgb::splat(0.5)));
    for (k, (name, v)) in quads.iter().enumerate() {
        d.objects.push(ObjectDesc { name: (*name).into(), loc: None });
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v.to_vec(), material: 0, object: k as u32, loc: None });
    }
    Scene::from_desc(d).unwrap()
}

/// The path of a file in ../shared (next to the repository), if present.
pub fn shared(rel: &str) -> Option<std::path::PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipping: {} not found (../shared is not beside the repository)", p.display());
        None
    }
}

/// The six faces of an axis-aligned box, wound outward (or inward for a room).
pub fn box_faces(lo: DVec3, hi: DVec3, inward: bool) -> Vec<Vec<DVec3>> {
    let c = [
        DVec3::new(lo.x, lo.y, lo.z),
        DVec3::new(hi.x, lo.y, lo.z),
        DVec3::new(hi.x, hi.y, lo.z),
        DVec3::new(lo.x, hi.y, lo.z),
        DVec3::new(lo.x, lo.y, hi.z),
        DVec3::new(hi.x, lo.y, hi.z),
        DVec3::new(hi.x, hi.y, hi.z),
        DVec3::new(lo.x, hi.y, hi.z),
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

/// A real model's geometry (`rel` under ../shared; `None` without it) inside a closed
/// furnace room 50 % larger than its bounds: every material grey ρ = 0.5 with Ke = 1, the
/// model two-sided. `one_sided_room`: the room's walls face inward only (else they are
/// two-sided too, and their outer sides face the void, where B = E exactly).
pub fn model_in_furnace(rel: &str, one_sided_room: bool) -> Option<Scene> {
    let path = shared(rel)?;
    let mut d = radiosity::scene::load(path.to_str().unwrap()).unwrap();
    for m in &mut d.materials {
        m.reflectance = Rgb::splat(0.5);
        m.emission = Rgb::ONE;
    }
    d.two_sided = true;
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for p in &d.polygons {
        for x in &p.vertices {
            lo = lo.min(*x);
            hi = hi.max(*x);
        }
    }
    let pad = (hi - lo) * 0.25;
    let obj = d.objects.len() as u32;
    d.objects.push(ObjectDesc { name: "furnace-room".into(), loc: None });
    let material = if one_sided_room {
        d.materials.push(MaterialDesc {
            emission: Rgb::ONE,
            two_sided: Some(false),
            ..MaterialDesc::diffuse("furnace-room", Rgb::splat(0.5))
        });
        d.materials.len() as u32 - 1
    } else {
        0
    };
    for f in box_faces(lo - pad, hi + pad, true) {
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: f, material, object: obj, loc: None });
    }
    d.camera = None;
    Some(Scene::from_desc(d).unwrap())
}

/// Uniform numbers in [0, 1) from a xorshift64 stream started at `seed` (non-zero): cheap,
/// reproducible randomness for the diagnostics.
pub fn xorshift(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}
