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
