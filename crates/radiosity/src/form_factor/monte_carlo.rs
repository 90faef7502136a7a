//! Monte Carlo form factors: cosine-weighted rays from stratified points of the sender.
//!
//! ```text
//! F_ij ≈ Σ_k w_k · [ray k first hits the front of j] / Σ_k w_k
//! ```
//!
//! A ray `k` starts at a point `x_k` of the sender `i` and leaves in a direction drawn with
//! density `cos θ / π` about the sender's normal, so the fraction of rays whose closest
//! hit is on `j` estimates `F_ij` with occlusion included (e.g. Cohen & Wallace 1993,
//! §4.10; the reference factors in `reference/cornell-box` were made the same way). The
//! `m × m` start points are jittered strata of the element's parameter square and the
//! `m × m` directions jittered strata of the cosine map (Malley's method), paired by a
//! random permutation ("padded" 2-D + 2-D stratification). `w_k` is the area Jacobian of
//! the element's bilinear parametrisation at the start point (exactly 1 on triangles and
//! parallelograms), so every element is sampled uniformly by area; dividing by `Σ w_k`
//! makes the rows of a closed scene sum to exactly 1.
//!
//! Rays ignore the sender's own polygon (planar: it cannot be hit), every polygon in its
//! plane (its coincident back copy under `--two-sided` included: hit only by rounding) and
//! the back faces of two-sided polygons (their front twin, coincident, is hit instead); a
//! ray that meets the back of a one-sided polygon is absorbed there and counts for nobody.
//!
//! **Covered parts.** The solvers want the factor of an element's *open* part (see
//! [`crate::mesh::coverage`]: floor under a box is covered). On an element that is partly
//! covered, a ray that starts in a covered cell ([`crate::mesh::Receivers::open_at`], the
//! coverage test's own [`crate::mesh::coverage::FINE_K`]² grid) is dropped from the
//! numerator *and* the denominator, so the row is the ray estimate over the open part and
//! still sums to at most 1. (Dividing the whole element's row by its open fraction instead
//! counted the covered part's view of the inside of a two-sided box as if the open part had
//! it: row sums up to 32 and a diverging solve on touching boxes, issue 9. Judging a ray by
//! its hit — dropped when it met a back face or a generated back copy — also dropped the
//! open part's rays to a two-sided lamp's back in a gap under the ceiling: 54.9 % of the
//! two-sided McGuire Cornell box's light escaped against 44.6 % with the other methods.)
//! Each row draws from
//! its own random stream (seed, row), so results do not depend on the thread count.

use glam::{DVec3, Vec3};

use super::{Context, RowSource};
use crate::accel::{Bvh, Ray};
use crate::sampling::{basis, cosine_hemisphere, rng_for, unit_f64};

/// Default rays per sender element.
pub const DEFAULT_RAYS: usize = 4096;

pub(crate) struct Rows<'a> {
    ctx: &'a Context<'a>,
    bvh: Bvh,
    /// Per BVH triangle: its element.
    owner: Vec<u32>,
    /// Per element: normal (f32) and whether its polygon is two-sided.
    normal: Vec<Vec3>,
    two_sided: Vec<bool>,
    tmin: f32,
}

impl<'a> Rows<'a> {
    pub fn new(ctx: &'a Context<'a>) -> Self {
        let (tris, owner) = ctx.mesh.triangles();
        let bvh = Bvh::build(&tris);
        let scene = ctx.scene;
        let normal = ctx.mesh.elements.iter().map(|e| e.normal.as_vec3()).collect();
        let two_sided = ctx
            .mesh
            .elements
            .iter()
            .map(|e| {
                let p = &scene.polygons[e.patch as usize];
                scene.materials[p.material as usize].two_sided
            })
            .collect();
        let tmin = (1e-7 * scene.diagonal()) as f32;
        Rows { ctx, bvh, owner, normal, two_sided, tmin }
    }
}

/// Accumulated weight per element, the elements touched, and the pairing permutation.
pub(crate) struct Scratch {
    acc: Vec<f64>,
    touched: Vec<u32>,
    perm: Vec<u32>,
}

impl Rows<'_> {
    /// True when patch `q` lies in the plane of a ray's start `x` (normal `n`): a ray that
    /// leaves the plane meets nothing in it, but the start point, rounded to f32, can lie
    /// a hair behind a coincident polygon (the sender's own generated back copy under
    /// `--two-sided`) and hit it at once. Those hits handed 8 % of some elements' rows to
    /// their own back copies, and a closed room holding office2's double-walled lamp
    /// housing (walls 0.002 apart) let 5 % of its light escape.
    #[inline]
    fn in_plane(&self, q: u32, x: DVec3, n: DVec3) -> bool {
        let (p, nq) = self.ctx.planes[q as usize];
        nq.dot(n).abs() > 1.0 - 1e-9 && nq.dot(x - p).abs() <= self.ctx.eps
    }
}

impl RowSource for Rows<'_> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        Scratch { acc: vec![0.0; self.ctx.mesh.len()], touched: Vec::new(), perm: Vec::new() }
    }

    fn row(&self, i: usize, s: &mut Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
        use rand::RngExt;
        let mesh = self.ctx.mesh;
        let ei = &mesh.elements[i];
        let (c, nv) = ei.corners(&mesh.positions);
        let m = (self.ctx.opts.mc_rays as f64).sqrt().ceil() as usize;
        let total = m * m;
        let mut rng = rng_for(self.ctx.opts.seed, i as u64);
        s.perm.clear();
        s.perm.extend(0..total as u32);
        for k in (1..total).rev() {
            let r = (unit_f64(rng.random::<u64>()) * (k + 1) as f64) as usize;
            s.perm.swap(k, r.min(k));
        }
        let (t, b) = basis(ei.normal);
        let n = ei.normal;
        let inv = 1.0 / m as f64;
        let mut wsum = 0.0;
        let patch = ei.patch;
        let open = self.ctx.receivers.open_fraction.get(i).copied().unwrap_or(1.0);
        let partly_covered = open > 0.0 && open < 1.0;
        for k in 0..total {
            let (pu, pv) = ((k % m) as f64, (k / m) as f64);
            let (u, v) = ((pu + rng.random::<f64>()) * inv, (pv + rng.random::<f64>()) * inv);
            let d = s.perm[k] as usize;
            let (du, dv) = ((d % m) as f64, (d / m) as f64);
            let (u1, u2) = ((du + rng.random::<f64>()) * inv, (dv + rng.random::<f64>()) * inv);
            let x = ei.point(&mesh.positions, u, v);
            let w = if nv == 4 {
                let dpu = (c[1] - c[0]) * (1.0 - v) + (c[2] - c[3]) * v;
                let dpv = c[3].lerp(c[2], u) - c[0].lerp(c[1], u);
                dpu.cross(dpv).length() / ei.area
            } else {
                1.0
            };
            let l = cosine_hemisphere(u1, u2);
            let dir: DVec3 = t * l.x + b * l.y + n * l.z;
            let dirf = dir.as_vec3();
            let ray = Ray::new(x.as_vec3(), dirf, self.tmin, f32::INFINITY);
            let hit = self.bvh.intersect_filtered(&ray, |prim| {
                let e = self.owner[prim as usize] as usize;
                let q = mesh.elements[e].patch;
                q == patch || (self.two_sided[e] && self.normal[e].dot(dirf) >= 0.0) || self.in_plane(q, x, n)
            });
            if partly_covered && !self.ctx.receivers.open_at(i, u, v) {
                continue; // started in the covered part: not part of the open area
            }
            wsum += w;
            if let Some(h) = hit {
                let j = self.owner[h.prim as usize];
                if self.normal[j as usize].dot(dirf) < 0.0 {
                    if s.acc[j as usize] == 0.0 {
                        s.touched.push(j);
                    }
                    s.acc[j as usize] += w;
                }
            }
        }
        let wsum = wsum.max(f64::MIN_POSITIVE);
        for &j in &s.touched {
            out.push((j, s.acc[j as usize] / wsum));
            s.acc[j as usize] = 0.0;
        }
        s.touched.clear();
        total as u64
    }
}
