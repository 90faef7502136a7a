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
    /// Per polygon: the other side of its two-sided pair when the two share one set of
    /// triangles in the hierarchy (the back copy's own triangles are left out), else
    /// [`NO_TWIN`]. A hit on such a triangle belongs to the side that faces the ray.
    twin: Vec<u32>,
}

/// Marks a polygon whose triangles are its own ([`SceneRays`]'s `twin`).
const NO_TWIN: u32 = u32::MAX;

/// True when `b` is `a` with its vertices in reverse order (the generated back copy).
fn reversed(a: &Polygon, b: &Polygon) -> bool {
    a.vertices.len() == b.vertices.len() && a.vertices.iter().zip(b.vertices.iter().rev()).all(|(x, y)| x == y)
}

/// Relative start/end offset of a visibility segment, as a fraction of its length; keeps
/// hits at the end points (on the polygons' neighbours at a shared edge) from counting.
pub const SEGMENT_EPS: f32 = 1e-4;

/// Relative distance within which two hits on a ray count as coincident (f32 precision of
/// the hit distance, with room to spare).
pub const COINCIDENT_T: f32 = 1e-5;

impl SceneRays {
    /// Builds the hierarchy over all polygons. The two sides of a two-sided polygon are
    /// coincident: only the front's triangles go into the hierarchy (half the triangles,
    /// and no pairs of identical boxes for the build to split), and a hit is given to the
    /// side that faces the ray.
    pub fn new(polygons: &[Polygon]) -> Self {
        let mut tris = Vec::new();
        let mut tri_polygon = Vec::new();
        let mut twin = vec![NO_TWIN; polygons.len()];
        for (pi, p) in polygons.iter().enumerate() {
            if p.two_sided && p.back_side {
                // validate.rs pushes the back copy right before its front.
                if polygons.get(pi + 1).is_some_and(|f| f.two_sided && !f.back_side && reversed(f, p)) {
                    twin[pi] = pi as u32 + 1;
                    twin[pi + 1] = pi as u32;
                    continue;
                }
            }
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
            twin,
        }
    }

    /// The polygon whose face a ray with direction `dir` meets on triangle `prim`: the
    /// triangle's polygon, or its twin when the ray comes from behind a shared pair.
    #[inline]
    pub fn polygon_hit(&self, prim: u32, dir: Vec3) -> u32 {
        let p = self.tri_polygon[prim as usize];
        let t = self.twin[p as usize];
        if t != NO_TWIN && self.normal[p as usize].dot(dir) > 0.0 {
            t
        } else {
            p
        }
    }

    /// The unit normal of polygon `p` (f32).
    #[inline]
    pub fn normal_of(&self, p: u32) -> Vec3 {
        self.normal[p as usize]
    }

    /// True when polygon `p` (of a triangle) is `q` or `q`'s coincident twin.
    #[inline]
    fn is_or_twin(&self, p: u32, q: u32) -> bool {
        p == q || self.twin[p as usize] == q
    }

    /// The underlying hierarchy (triangle ids index [`SceneRays::polygon_of`]).
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// The other side of polygon `p`'s two-sided pair, if it has one.
    #[inline]
    pub fn twin_of(&self, p: u32) -> Option<u32> {
        let t = self.twin[p as usize];
        (t != NO_TWIN).then_some(t)
    }

    /// The polygon a triangle belongs to (the front of a two-sided pair; see
    /// [`SceneRays::polygon_hit`]).
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
            self.is_or_twin(p, pa) || self.is_or_twin(p, pb)
        })
    }

    /// True if the segment from `a` (on polygon `from`) to the point `b` (a light, on no
    /// polygon) meets no other polygon; a polygon through `b` itself does not block it.
    #[inline]
    pub fn reaches(&self, a: DVec3, from: u32, b: DVec3) -> bool {
        let ray = Ray::new(a.as_vec3(), (b - a).as_vec3(), 0.0, 1.0 - SEGMENT_EPS);
        !self.bvh.occluded_filtered(&ray, |prim| self.is_or_twin(self.tri_polygon[prim as usize], from))
    }

    /// Closest polygon whose visible face is hit by a ray from `origin` (optionally leaving
    /// polygon `from`): the back face of one side of a two-sided pair is skipped, since its
    /// coincident twin faces the ray, and where the closest hit is the back face of a
    /// one-sided polygon, a front face coincident with it (within [`COINCIDENT_T`] of the
    /// distance: the other side of a thin slab modelled as two one-sided polygons) wins the
    /// tie. Returns the hit and the polygon index.
    #[inline]
    pub fn closest_facing(&self, origin: Vec3, dir: Vec3, tmax: f32, from: Option<u32>) -> Option<(Hit, u32)> {
        let skip = |p: u32| from.is_some_and(|f| self.is_or_twin(p, f));
        let ray = Ray::new(origin, dir, 0.0, tmax);
        let h = self.bvh.intersect_filtered(&ray, |prim| {
            let p = self.tri_polygon[prim as usize];
            skip(p)
                || (self.two_sided[p as usize]
                    && self.twin[p as usize] == NO_TWIN
                    && self.normal[p as usize].dot(dir) > 0.0)
        })?;
        let p = self.polygon_hit(h.prim, dir);
        if self.normal[p as usize].dot(dir) >= 0.0 {
            let tol = COINCIDENT_T * h.t;
            let tie = Ray::new(origin, dir, h.t - tol, (h.t + tol).min(tmax));
            let front = self.bvh.intersect_filtered(&tie, |prim| {
                let q = self.tri_polygon[prim as usize];
                skip(q) || (self.twin[q as usize] == NO_TWIN && self.normal[q as usize].dot(dir) >= 0.0)
            });
            if let Some(f) = front {
                return Some((f, self.polygon_hit(f.prim, dir)));
            }
        }
        Some((h, p))
    }

    /// True if a ray from `origin` (optionally leaving polygon `from`) meets no polygon,
    /// either side: it leaves the scene and sees the sky.
    #[inline]
    pub fn escapes(&self, origin: Vec3, dir: Vec3, from: Option<u32>) -> bool {
        let ray = Ray::new(origin, dir, 0.0, f32::INFINITY);
        !self.bvh.occluded_filtered(&ray, |prim| from.is_some_and(|f| self.is_or_twin(self.tri_polygon[prim as usize], f)))
    }

    /// Closest polygon hit by a ray from `origin` (optionally leaving polygon `from`),
    /// returning the hit and the polygon index.
    #[inline]
    pub fn closest(&self, origin: Vec3, dir: Vec3, tmax: f32, from: Option<u32>) -> Option<(Hit, u32)> {
        let ray = Ray::new(origin, dir, 0.0, tmax);
        let h = match from {
            Some(f) => self.bvh.intersect_filtered(&ray, |prim| self.is_or_twin(self.tri_polygon[prim as usize], f)),
            None => self.bvh.intersect(&ray),
        }?;
        Some((h, self.polygon_hit(h.prim, dir)))
    }
}
