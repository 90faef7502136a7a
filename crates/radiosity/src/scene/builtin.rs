//! Built-in scenes: `cornell` (the default) and `furnace`.
//!
//! `cornell` is the Cornell box as measured by the Cornell Program of Computer Graphics
//! (millimetres, 19 planar quads, open front) with the common RGB reflectances and the light
//! `Ke 17 12 4`, identical to `../shared/scenes/cornell-box` (facts, public data), with its
//! camera. `furnace` is a closed unit cube whose six inward-facing walls all have
//! reflectance ρ = 0.5 and emit radiance L_e = 1: every point then has radiosity
//! B = E/(1−ρ) = π·L_e/(1−ρ) = 2π exactly — the classic furnace test.

use std::path::Path;

use glam::DVec3;

use super::{obj, Camera, MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
use crate::Rgb;

/// Names accepted by [`by_name`].
pub const NAMES: [&str; 2] = ["cornell", "furnace"];

const CORNELL_OBJ: &str = include_str!("../../data/cornell/cornell_box.obj");
const CORNELL_MTL: &str = include_str!("../../data/cornell/cornell_box.mtl");
const CORNELL_CAMERA: &str = include_str!("../../data/cornell/camera.json");

/// Furnace parameters: reflectance of every wall.
pub const FURNACE_REFLECTANCE: f64 = 0.5;
/// Furnace parameters: emitted radiance of every wall.
pub const FURNACE_RADIANCE: f64 = 1.0;

/// A built-in scene by name, or None.
pub fn by_name(name: &str) -> Option<SceneDesc> {
    match name {
        "cornell" => Some(cornell()),
        "furnace" => Some(furnace(FURNACE_REFLECTANCE, FURNACE_RADIANCE)),
        _ => None,
    }
}

/// The Cornell box.
pub fn cornell() -> SceneDesc {
    let file = Path::new("cornell_box.obj");
    let mut d = obj::parse_obj(CORNELL_OBJ, file, |_, _| obj::parse_mtl(CORNELL_MTL, Path::new("cornell_box.mtl")))
        .expect("the built-in Cornell box parses");
    d.name = "cornell".into();
    d.camera = Some(Camera::from_json_str(CORNELL_CAMERA, Path::new("camera.json")).expect("built-in camera"));
    d
}

/// A closed unit cube (walls facing inwards) with uniform reflectance and emission.
pub fn furnace(reflectance: f64, radiance: f64) -> SceneDesc {
    let c = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let faces: [(&str, [DVec3; 4]); 6] = [
        ("floor", [c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)]),
        ("ceiling", [c(0., 1., 0.), c(0., 1., 1.), c(1., 1., 1.), c(1., 1., 0.)]),
        ("left", [c(0., 0., 0.), c(0., 0., 1.), c(0., 1., 1.), c(0., 1., 0.)]),
        ("right", [c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)]),
        ("back", [c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)]),
        ("front", [c(0., 0., 0.), c(0., 1., 0.), c(1., 1., 0.), c(1., 0., 0.)]),
    ];
    let mut d = SceneDesc { name: "furnace".into(), ..Default::default() };
    d.materials.push(MaterialDesc {
        base_texture: None,
        emission_texture: None,
        thermal: None,
        name: "furnace".into(),
        reflectance: Rgb::splat(reflectance),
        emission: Rgb::splat(radiance),
        two_sided: None,
        loc: None,
    });
    for (i, (name, v)) in faces.iter().enumerate() {
        // Orient each wall so that its front (right-hand rule) faces the inside.
        let mut v = v.to_vec();
        let n = super::newell_normal(&v);
        let centre = v.iter().copied().sum::<DVec3>() / 4.0;
        if n.dot(DVec3::splat(0.5) - centre) < 0.0 {
            v.reverse();
        }
        d.objects.push(ObjectDesc { name: (*name).into(), loc: None });
        d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v, material: 0, object: i as u32, loc: None });
    }
    d.camera = Some(Camera { position: c(0.5, 0.5, 0.05), look_at: c(0.5, 0.5, 1.0), up: DVec3::Y, vfov_deg: 60.0 });
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn cornell_has_19_objects_and_inward_walls() {
        let s = Scene::from_desc(cornell()).unwrap();
        assert_eq!(s.objects.len(), 19);
        // 18 planar quads + the non-planar red wall split into two triangles.
        assert_eq!(s.polygons.len(), 20);
        let floor = &s.polygons[0];
        assert!(floor.normal.y > 0.999);
        let area: f64 = s.polygons.iter().filter(|p| p.object == 0).map(|p| p.area).sum();
        assert!((area - 308231.04).abs() < 1e-6 * area, "floor area {area}");
    }

    #[test]
    fn furnace_normals_point_inwards() {
        let s = Scene::from_desc(furnace(0.5, 1.0)).unwrap();
        for p in &s.polygons {
            let to_center = DVec3::splat(0.5) - p.centroid();
            assert!(p.normal.dot(to_center) > 0.0);
            assert!((p.area - 1.0).abs() < 1e-12);
        }
    }
}
