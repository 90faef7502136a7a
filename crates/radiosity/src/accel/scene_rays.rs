//! Visibility queries between points on the scene's polygons.

use glam::{DVec3, Vec3};

use super::{Bvh, Hit, Ray};
use crate::scene::Polygon;

/// A BVH over the triangles of the scene's polygons (fan triangulation of each convex
/// polygon), with the polygon of every triangle, answering "can point a on polygon pa see
/// point b on polygon pb?".
#[derive(Clone, Debug, Default)]
pub struct SceneRays {
    bvh: Bvh,
    tri_polygon: Vec<u32>,
    /// Per polygon: one side of a two-sided pair (its back face is hidden by its twin).
    two_sided: Vec<bool>,
    /// Per polygon: unit normal, f32.
    normal: Vec<Vec3>,
}

/// Relative start/end offset of a visibility segment, as a fraction of its length; keeps
/// hits at the end points (on the polygons' neighbours at a shared edge) from counting.
pub const SEGMENT_EPS: f32 = 1e-4;

impl SceneRays {
    /// Builds the hierarchy over all polygons.
    pub fn new(polygons: &[Polygon]) -> Self {
        let mut tris = Vec::new();
        let mut tri_polygon = Vec::new();
        for (pi, p) in polygons.iter().enumerate() {
            let v = &p.vertices;
            for i in 1..v.len() - 1 {
                tris.push([v[0].as_vec3(), v[i].as_vec3(), v[i + 1].as_vec3()]);
                tri_polygon.push(pi as u32);
            }
        }
        SceneRays {
            bvh: Bvh::build(&tris),
            tri_polygon,
            two_sided: polygons.iter().map(|p| p.two_sided).collect(),
            normal: polygons.iter().map(|p| p.normal.as_vec3()).collect(),
        }
    }

    /// The underlying hierarchy (triangle ids index [`SceneRays::polygon_of`]).
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// The polygon a triangle belongs to.
    #[inline]
    pub fn polygon_of(&self, prim: u32) -> u32 {
        self.tri_polygon[prim as usize]
    }

    /// True if the open segment from `a` (on polygon `pa`) to `b` (on polygon `pb`) meets no
    /// other polygon. The two end polygons are ignored: planar polygons cannot block a
    /// segment that leaves them.
    #[inline]
    pub fn visible(&self, a: DVec3, pa: u32, b: DVec3, pb: u32) -> bool {
        let o = a.as_vec3();
        let d = (b - a).as_vec3();
        let ray = Ray::new(o, d, SEGMENT_EPS, 1.0 - SEGMENT_EPS);
        !self.bvh.occluded_filtered(&ray, |prim| {
            let p = self.tri_polygon[prim as usize];
            p == pa || p == pb
        })
    }

    /// Closest polygon whose visible face is hit by a ray from `origin` (optionally leaving
    /// polygon `from`): the back face of one side of a two-sided pair is skipped, since its
    /// coincident twin faces the ray. Returns the hit and the polygon index.
    #[inline]
    pub fn closest_facing(&self, origin: Vec3, dir: Vec3, tmax: f32, from: Option<u32>) -> Option<(Hit, u32)> {
        let ray = Ray::new(origin, dir, 0.0, tmax);
        let h = self.bvh.intersect_filtered(&ray, |prim| {
            let p = self.tri_polygon[prim as usize];
            Some(p) == from || (self.two_sided[p as usize] && self.normal[p as usize].dot(dir) > 0.0)
        })?;
        Some((h, self.tri_polygon[h.prim as usize]))
    }

    /// Closest polygon hit by a ray from `origin` (optionally leaving polygon `from`),
    /// returning the hit and the polygon index.
    #[inline]
    pub fn closest(&self, origin: Vec3, dir: Vec3, tmax: f32, from: Option<u32>) -> Option<(Hit, u32)> {
        let ray = Ray::new(origin, dir, 0.0, tmax);
        let h = match from {
            Some(f) => self.bvh.intersect_filtered(&ray, |prim| self.tri_polygon[prim as usize] == f),
            None => self.bvh.intersect(&ray),
        }?;
        Some((h, self.tri_polygon[h.prim as usize]))
    }
}
