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
        d.polygons.push(PolygonDesc { vertices: v.to_vec(), material: 0, object: k as u32, loc: None });
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
