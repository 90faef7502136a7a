//! Stage 2: meshing — input polygons (patches) subdivided into elements.
//!
//! Radiosity is solved per element (piecewise-constant basis, Cohen & Wallace 1993, ch. 3).
//! Quadrilaterals are cut into an `nu × nv` grid of planar sub-quads (bilinear
//! parametrisation), triangles into `k²` similar sub-triangles, other convex polygons into
//! fan triangles subdivided with one `k` so their shared edges match. Inside a patch the
//! elements share vertices; across patches [`crate::reconstruct`] welds vertices that
//! coincide on the same plane and material.
//!
//! The target element size is in scene units; [`default_size`] scales with the scene.

pub mod coverage;
pub mod lit_sides;
pub mod locate;
pub mod adaptive;
pub mod atlas;
mod uniform;

use glam::DVec3;

pub use coverage::{Receivers, FINE_K};
pub use locate::Locator;
pub use uniform::{count_uniform, mesh_uniform, mesh_uniform_with};

use crate::scene::Scene;

/// Marks the unused fourth vertex of a triangular element.
pub const NO_VERTEX: u32 = u32::MAX;

/// One element: a planar convex triangle or quadrilateral of one patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Element {
    /// Vertex indices into [`Mesh::positions`], counter-clockwise about the normal;
    /// `vertices[3] == NO_VERTEX` for triangles.
    pub vertices: [u32; 4],
    /// The scene polygon (patch) it belongs to.
    pub patch: u32,
    /// Area in scene units².
    pub area: f64,
    /// Area centroid.
    pub centroid: DVec3,
    /// Unit normal (the patch's).
    pub normal: DVec3,
}

/// The point at `(u, v) ∈ [0,1]²` of a quad (bilinear) or triangle (`c[0..3]`, area-uniform
/// for uniform `(u, v)`): [`Element::point`] on corners already loaded.
#[inline]
pub fn point_on(c: &[DVec3; 4], quad: bool, u: f64, v: f64) -> DVec3 {
    if quad {
        let a = c[0].lerp(c[1], u);
        let b = c[3].lerp(c[2], u);
        a.lerp(b, v)
    } else {
        let su = u.sqrt();
        c[0] * (1.0 - su) + c[1] * (su * (1.0 - v)) + c[2] * (su * v)
    }
}

impl Element {
    /// 3 or 4.
    #[inline]
    pub fn vertex_count(&self) -> usize {
        if self.vertices[3] == NO_VERTEX {
            3
        } else {
            4
        }
    }

    /// Corner positions (the first `vertex_count()` are valid).
    #[inline]
    pub fn corners(&self, positions: &[DVec3]) -> ([DVec3; 4], usize) {
        let n = self.vertex_count();
        let mut c = [DVec3::ZERO; 4];
        for k in 0..n {
            c[k] = positions[self.vertices[k] as usize];
        }
        (c, n)
    }

    /// A point on the element for (u, v) ∈ [0,1)²: bilinear for quads, area-uniform for
    /// triangles. Uniform (u, v) give area-uniform points on parallelograms and triangles,
    /// and nearly so on other convex quads.
    #[inline]
    pub fn point(&self, positions: &[DVec3], u: f64, v: f64) -> DVec3 {
        let (c, n) = self.corners(positions);
        point_on(&c, n == 4, u, v)
    }

    /// The (u, v) ∈ [0,1]² of a point on (or projected onto) the element: the inverse of
    /// [`Element::point`] (barycentric for triangles, a few Gauss–Newton steps of the
    /// bilinear map for quads), clamped to the domain.
    pub fn parameters(&self, positions: &[DVec3], x: DVec3) -> (f64, f64) {
        let (c, n) = self.corners(positions);
        if n == 4 {
            let (mut u, mut v) = (0.5, 0.5);
            for _ in 0..6 {
                let p = self.point(positions, u, v);
                let du = (c[1] - c[0]) * (1.0 - v) + (c[2] - c[3]) * v;
                let dv = c[3].lerp(c[2], u) - c[0].lerp(c[1], u);
                let r = x - p;
                let (a, b, d) = (du.dot(du), du.dot(dv), dv.dot(dv));
                let det = a * d - b * b;
                if det.abs() <= f64::MIN_POSITIVE {
                    break;
                }
                let (gu, gv) = (du.dot(r), dv.dot(r));
                u = (u + (d * gu - b * gv) / det).clamp(0.0, 1.0);
                v = (v + (a * gv - b * gu) / det).clamp(0.0, 1.0);
            }
            (u, v)
        } else {
            let (e1, e2, r) = (c[1] - c[0], c[2] - c[0], x - c[0]);
            let (a, b, d) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
            let det = (a * d - b * b).max(f64::MIN_POSITIVE);
            let (g1, g2) = (e1.dot(r), e2.dot(r));
            let b1 = ((d * g1 - b * g2) / det).max(0.0);
            let b2 = ((a * g2 - b * g1) / det).max(0.0);
            let su = (b1 + b2).min(1.0);
            let v = if su > 0.0 { (b2 / (b1 + b2)).clamp(0.0, 1.0) } else { 0.5 };
            (su * su, v)
        }
    }
}

/// The elements of one patch are contiguous: `first .. first + count`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PatchElements {
    /// First element.
    pub first: u32,
    /// Number of elements.
    pub count: u32,
}

/// The element mesh of a scene.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<DVec3>,
    /// Elements, grouped by patch.
    pub elements: Vec<Element>,
    /// Per scene polygon, its elements.
    pub patches: Vec<PatchElements>,
    /// The target element size used, in scene units.
    pub target_size: f64,
}

impl Mesh {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }
    /// True if there are no elements.
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }
    /// Triangles of all elements (quads split along v0–v2) with the element of each.
    pub fn triangles(&self) -> (Vec<[glam::Vec3; 3]>, Vec<u32>) {
        let mut tris = Vec::with_capacity(self.elements.len() * 2);
        let mut owner = Vec::with_capacity(self.elements.len() * 2);
        for (ei, e) in self.elements.iter().enumerate() {
            let (c, n) = e.corners(&self.positions);
            tris.push([c[0].as_vec3(), c[1].as_vec3(), c[2].as_vec3()]);
            owner.push(ei as u32);
            if n == 4 {
                tris.push([c[0].as_vec3(), c[2].as_vec3(), c[3].as_vec3()]);
                owner.push(ei as u32);
            }
        }
        (tris, owner)
    }
}

/// The default element size: 1/36 of the scene's bounding-box diagonal (about 3,300
/// elements for the Cornell box: per-object radiance within 1 % of the path-traced
/// reference and a 256² final-gather image at 1.6 % light-masked RMSE in about 2 s; see
/// BENCHMARKS.md).
pub fn default_size(scene: &Scene) -> f64 {
    scene.diagonal() / 36.0
}
