//! Uniform subdivision of every patch to a target element size.

use std::collections::HashMap;

use glam::DVec3;

use super::{Element, Mesh, PatchElements, NO_VERTEX};
use crate::scene::{polygon_centroid, Scene};

/// Number of elements [`mesh_uniform`] would create (without creating them), saturating.
pub fn count_uniform(scene: &Scene, size: f64) -> u64 {
    let size = if size.is_finite() && size > 0.0 { size } else { f64::INFINITY };
    let steps = |len: f64| -> u64 { ((len / size).ceil()).clamp(1.0, 1e9) as u64 };
    let mut total: u64 = 0;
    for poly in &scene.polygons {
        let v = &poly.vertices;
        let n = if v.len() == 4 {
            let nu = steps((v[1] - v[0]).length().max((v[2] - v[3]).length()));
            let nv = steps((v[3] - v[0]).length().max((v[2] - v[1]).length()));
            nu.saturating_mul(nv)
        } else {
            let mut longest: f64 = 0.0;
            for k in 1..v.len() - 1 {
                let (a, b, c) = (v[0], v[k], v[k + 1]);
                longest = longest.max((b - a).length()).max((c - b).length()).max((a - c).length());
            }
            let k = steps(longest);
            k.saturating_mul(k).saturating_mul(v.len() as u64 - 2)
        };
        total = total.saturating_add(n);
    }
    total
}

/// Subdivides every polygon of `scene` into elements no larger than `size` (scene units)
/// along any edge of a quadrilateral, and no longer than `size·√2` (the diagonal of a
/// `size × size` square) along any edge of a triangle: a right triangle cut to `size` along
/// its hypotenuse would get four times the elements of the square it is half of. `size <= 0` or non-finite leaves each polygon whole (one element per
/// triangle/quad, fans for larger polygons).
pub fn mesh_uniform(scene: &Scene, size: f64) -> Mesh {
    let size = if size.is_finite() && size > 0.0 { size } else { f64::INFINITY };
    let mut mesh = Mesh { target_size: size, ..Default::default() };
    for (pi, poly) in scene.polygons.iter().enumerate() {
        let first = mesh.elements.len() as u32;
        let mut b = PatchBuilder { mesh: &mut mesh, patch: pi as u32, normal: poly.normal, map: HashMap::new() };
        let v = &poly.vertices;
        let steps = |len: f64| -> usize { ((len / size).ceil() as usize).clamp(1, 100_000) };
        if v.len() == 4 {
            let nu = steps((v[1] - v[0]).length().max((v[2] - v[3]).length()));
            let nv = steps((v[3] - v[0]).length().max((v[2] - v[1]).length()));
            let p = |i: usize, j: usize| {
                let (u, t) = (i as f64 / nu as f64, j as f64 / nv as f64);
                v[0].lerp(v[1], u).lerp(v[3].lerp(v[2], u), t)
            };
            for j in 0..nv {
                for i in 0..nu {
                    b.push(&[p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
                }
            }
        } else {
            // Fan triangles (a triangle is its own fan) with a common k.
            let mut longest: f64 = 0.0;
            for k in 1..v.len() - 1 {
                let (a, bb, c) = (v[0], v[k], v[k + 1]);
                longest = longest.max((bb - a).length()).max((c - bb).length()).max((a - c).length());
            }
            // A quad element's longest extent is its diagonal, size·√2; give triangle
            // elements the same.
            let k = steps(longest / std::f64::consts::SQRT_2);
            for f in 1..v.len() - 1 {
                let (a, e1, e2) = (v[0], v[f] - v[0], v[f + 1] - v[0]);
                let p = |i: usize, j: usize| a + e1 * (i as f64 / k as f64) + e2 * (j as f64 / k as f64);
                for j in 0..k {
                    for i in 0..k - j {
                        b.push(&[p(i, j), p(i + 1, j), p(i, j + 1)]);
                        if i + j + 1 < k {
                            b.push(&[p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
                        }
                    }
                }
            }
        }
        let count = mesh.elements.len() as u32 - first;
        mesh.patches.push(PatchElements { first, count });
    }
    mesh
}

struct PatchBuilder<'a> {
    mesh: &'a mut Mesh,
    patch: u32,
    normal: DVec3,
    map: HashMap<[u64; 3], u32>,
}

impl PatchBuilder<'_> {
    fn vertex(&mut self, p: DVec3) -> u32 {
        // Grid points of one patch are computed by the same formula from the same corners,
        // so coincident points are bit-identical except along fan edges; round lightly.
        let key = [round_key(p.x), round_key(p.y), round_key(p.z)];
        let positions = &mut self.mesh.positions;
        *self.map.entry(key).or_insert_with(|| {
            positions.push(p);
            (positions.len() - 1) as u32
        })
    }

    fn push(&mut self, corners: &[DVec3]) {
        let area = 0.5 * crate::scene::newell_normal(corners).length();
        if !(area > 0.0) {
            return;
        }
        let mut vs = [NO_VERTEX; 4];
        for (k, c) in corners.iter().enumerate() {
            vs[k] = self.vertex(*c);
        }
        self.mesh.elements.push(Element {
            vertices: vs,
            patch: self.patch,
            area,
            centroid: polygon_centroid(corners),
            normal: self.normal,
        });
    }
}

/// Rounds to ~40 significant bits so that points equal up to rounding share a key.
pub(super) fn round_key(x: f64) -> u64 {
    let b = (x + 0.0).to_bits(); // +0.0 folds -0.0 into 0.0
    (b + (1 << 11)) >> 12
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{builtin, Scene};

    #[test]
    fn subdivision_preserves_area_and_shares_vertices() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let mesh = mesh_uniform(&scene, 50.0);
        for (pi, p) in scene.polygons.iter().enumerate() {
            let pe = mesh.patches[pi];
            let a: f64 = mesh.elements[pe.first as usize..(pe.first + pe.count) as usize].iter().map(|e| e.area).sum();
            assert!((a - p.area).abs() < 1e-9 * p.area, "patch {pi}: {a} vs {}", p.area);
        }
        // A quad cut into nu x nv has (nu+1)(nv+1) vertices, far fewer than 4 per element.
        assert!(mesh.positions.len() < 2 * mesh.elements.len());
        let floor = mesh.patches[0];
        assert_eq!(floor.count, 12 * 12);
    }

    #[test]
    fn triangle_subdivision_is_conforming() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        // The red wall is two triangles (non-planar input).
        let tri_patch = scene.polygons.iter().position(|p| p.vertices.len() == 3).unwrap();
        let mesh = mesh_uniform(&scene, 100.0);
        let pe = mesh.patches[tri_patch];
        let k = (scene.polygons[tri_patch].vertices.windows(2).map(|w| (w[1] - w[0]).length()).fold(0.0, f64::max)
            / (100.0 * std::f64::consts::SQRT_2))
            .ceil() as u32;
        assert!(pe.count >= k * k);
        for e in &mesh.elements[pe.first as usize..(pe.first + pe.count) as usize] {
            assert!(e.normal.dot(scene.polygons[tri_patch].normal) > 0.999999);
            assert_eq!(e.vertex_count(), 3);
        }
    }
}
