//! Point-to-polygon analytic form factors with ray-sampled visibility
//! (Wallace, Elmquist & Haines 1989, "A ray tracing algorithm for progressive radiosity").
//!
//! ```text
//! F_ij ≈ 1/m · Σ_{s=1..m} F(dA_{x_s} → A_j) · V̂(x_s, A_j)
//! ```
//!
//! `x_s` are the open points of a fixed `k×k` grid on the receiver `i` (k grows as the
//! pair gets closer: 1 when the distance exceeds four element sizes, up to
//! `max_receiver_samples`; points inside closed geometry are excluded, see
//! [`crate::mesh::coverage`]);
//! `F(dA → A_j)` is the exact contour integral ([`super::kernel`]); `V̂` is the fraction of
//! `visibility_samples²` rays from `x_s` to stratified points of `j` that reach it. A pair
//! sampled on the finest grid (nearer than about 1.7 element sizes) whose receiver is wholly
//! open takes the exact unoccluded `F_ij` instead ([`super::analytic`], the double contour
//! integral) times the kernel-weighted visible share at those points: at close range the
//! kernel is a step or a singularity over the receiver that `k × k` points resolve only to
//! `1/k`, and it kept 5 % of a lamp's back light from the ceiling 0.01 above it. Rows of
//! a closed, unoccluded enclosure sum to one exactly (up to rounding), which is what the
//! furnace test needs. Where two coplanar polygons facing the same way overlap (a rug on a
//! floor; the back copy of a two-sided box's bottom on the floor under it), both would pass
//! the visibility test and the overlap would count twice (row sums up to 1.39 on a box in a
//! two-sided furnace, issue 9): a sample on the overlap counts only for the lower-numbered
//! polygon. Each row draws from its own random stream (seed, row), so results
//! do not depend on the thread count.

use glam::DVec3;

use super::kernel::{point_to_point, point_to_polygon};
use super::{Context, RowSource};
use crate::mesh::coverage::MAX_K;
use crate::sampling::{rng_for, stratified, Rng};

/// Patches with at least this many elements get the far-field kernel with patch
/// renormalisation.
const BIG_PATCH: u32 = 8;

pub(crate) struct Rows<'a> {
    ctx: &'a Context<'a>,
    /// Per element of a patch with coincident twins ([`Context::twins`], the lower-numbered
    /// coplanar, same-facing polygons that overlap it and own the overlap): its convex
    /// overlaps with them, cut from its kernel; empty for every other element.
    element_cuts: Vec<Vec<Vec<DVec3>>>,
    /// The same per patch (for the exact patch factor of large patches).
    patch_cuts: Vec<Vec<Vec<DVec3>>>,
}

impl<'a> Rows<'a> {
    pub fn new(ctx: &'a Context<'a>) -> Self {
        let (scene, mesh) = (ctx.scene, ctx.mesh);
        let patch_cuts: Vec<Vec<Vec<DVec3>>> =
            scene.polygons.iter().zip(&ctx.twins).map(|(p, t)| if t.is_empty() { Vec::new() } else { overlaps(&p.vertices, t, scene, ctx.eps) }).collect();
        let element_cuts = mesh
            .elements
            .iter()
            .map(|e| {
                let t = &ctx.twins[e.patch as usize];
                if t.is_empty() {
                    return Vec::new();
                }
                let (c, n) = e.corners(&mesh.positions);
                overlaps(&c[..n], t, scene, ctx.eps)
            })
            .collect();
        Rows { ctx, element_cuts, patch_cuts }
    }
}

/// Visibility points, the row (column, factor, far, far weight), the patch the list is for, its facing
/// patches.
pub(crate) type Scratch = (Vec<(f64, f64)>, Vec<(u32, f64, bool, f64)>, u32, Vec<u32>);

impl RowSource for Rows<'_> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        (Vec::new(), Vec::new(), u32::MAX, Vec::new())
    }

    fn row(&self, i: usize, s: &mut Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
        let (vis_pts, row, cached_patch, patch_list) = s;
        let ctx = self.ctx;
        let (scene, mesh, rays, receivers, opts, eps) = (ctx.scene, ctx.mesh, ctx.rays, ctx.receivers, ctx.opts, ctx.eps);
        let ei = &mesh.elements[i];
        let pi = ei.patch;
        if *cached_patch != pi {
            *cached_patch = pi;
            ctx.facing_patches(pi, patch_list);
        }
        let mut rng = rng_for(opts.seed, i as u64);
        let size_i = ei.area.sqrt();
        let (ci, ni) = ei.corners(&mesh.positions);
        let mut nrays = 0u64;
        row.clear();
        let Some(&c1) = receivers.points(i, 1).first() else {
            return 0; // entirely covered: receives nothing
        };
        let kv = opts.visibility_samples.max(1);
        // Visible fraction of element j seen from x (kv² stratified rays).
        let ei_normal = ei.normal;
        let mut visibility = |x: DVec3, j: u32, q: u32, rng: &mut Rng, nrays: &mut u64| {
            let ej = &mesh.elements[j as usize];
            let owned_by_twin = |y: DVec3| {
                ctx.twins[q as usize].iter().any(|&t| {
                    let p = &scene.polygons[t as usize];
                    super::geom::inside_convex(y, &p.vertices, p.normal, eps)
                })
            };
            stratified(kv, rng, vis_pts);
            // Each sample is weighted by the point-to-point kernel cos θx cos θy / r²
            // (the sampling density is uniform): at close range the factor comes from the
            // part of j right in front of x, and a plain count of visible samples made a
            // sliver seen past a coincident twin count like the whole element (the inside
            // of office2's and the classroom's thin slabs: raw row sums of 1.7, issue 9).
            let weight = |y: DVec3| {
                let d = y - x;
                let r2 = d.length_squared().max(f64::MIN_POSITIVE);
                (ei_normal.dot(d).max(0.0) * (-ej.normal.dot(d)).max(0.0) / (r2 * r2)).min(f64::MAX / 1e6)
            };
            let (mut seen, mut tried, mut count) = (0.0f64, 0.0f64, 0u32);
            // One visibility sample y on j. The overlap with a twin is not part of this
            // element's factor (its kernel leaves it out exactly, see `kernel` below): its
            // samples do not count.
            let test = |y: DVec3, seen: &mut f64, tried: &mut f64, count: &mut u32| {
                if ei_normal.dot(y - x) <= 0.0 || owned_by_twin(y) {
                    return;
                }
                *count += 1;
                let w = weight(y);
                *tried += w;
                if rays.visible(x, pi, y, q) {
                    *seen += w;
                }
            };
            for &(a, b) in vis_pts.iter() {
                test(ej.point(&mesh.positions, a, b), &mut seen, &mut tried, &mut count);
            }
            if count == 0 {
                // No sample fell on the part of j in front of x (a large element that x
                // sees only a sliver of): test that part itself, its centroid and the
                // midpoints towards its corners. Counting it as wholly visible let the
                // inside of a thin slab see a desk through the slab's top (office2: raw row
                // sums of 1.3, issue 9).
                let (cj, nv) = ej.corners(&mesh.positions);
                let mut front = Vec::new();
                super::geom::clip_halfspace(&cj[..nv], |p| ei_normal.dot(p - x), eps, &mut front);
                if front.len() >= 3 {
                    let c = front.iter().copied().sum::<DVec3>() / front.len() as f64;
                    for y in std::iter::once(c).chain(front.iter().map(|v| c.lerp(*v, 0.5))) {
                        test(y, &mut seen, &mut tried, &mut count);
                    }
                }
            }
            *nrays += count as u64;
            if count == 0 || !(tried > 0.0) {
                0.0
            } else {
                (seen / tried).clamp(0.0, 1.0)
            }
        };
        // Near pairs get k×k receiver points; far pairs the single point c1. The
        // extra exchange D that the finer sets find with near neighbours is taken
        // from the far field (scale α), so each row sums exactly to the unoccluded
        // total seen from c1 — one in a closed room (the furnace test).
        let mut near_excess = 0.0;
        let mut exact_scratch = super::analytic::Scratch::default();
        for &q in patch_list.iter() {
            let pe = mesh.patches[q as usize];
            let poly_q = &scene.polygons[q as usize];
            // Large patches: far elements use the point-to-point kernel and are then
            // scaled so that, with the exact near ones, they add up to the exact
            // factor to the whole patch (contour integral) — cheap and still exact in
            // total, which keeps closed rooms closed.
            let big = pe.count >= BIG_PATCH;
            let exact_q = if big {
                let cut = &self.patch_cuts[q as usize];
                (point_to_polygon(c1, ei.normal, &poly_q.vertices, poly_q.normal)
                    - cut.iter().map(|o| point_to_polygon(c1, ei.normal, o, poly_q.normal)).sum::<f64>())
                .max(0.0)
            } else {
                0.0
            };
            let far_start = row.len();
            let mut approx_far_q = 0.0;
            let mut near_f1_q = 0.0;
            for j in pe.first..pe.first + pe.count {
                let ej = &mesh.elements[j as usize];
                let (cj, nv) = ej.corners(&mesh.positions);
                let cj = &cj[..nv];
                // Element-level cull.
                if !cj.iter().any(|v| ei.normal.dot(*v - ei.centroid) > eps) {
                    continue;
                }
                // The parts of j that lower-numbered coincident twins own are left out of
                // its kernel exactly (contour integrals of the convex overlaps).
                let cut = &self.element_cuts[j as usize];
                let cut_fraction = (cut.iter().map(|o| super::geom::area_3d(o)).sum::<f64>() / ej.area).clamp(0.0, 1.0);
                let kernel = |x: DVec3| {
                    let f = point_to_polygon(x, ei.normal, cj, ej.normal);
                    if cut.is_empty() {
                        f
                    } else {
                        (f - cut.iter().map(|o| point_to_polygon(x, ei.normal, o, ej.normal)).sum::<f64>()).max(0.0)
                    }
                };
                let d = (ej.centroid - ei.centroid).length();
                let size_j = ej.area.sqrt();
                let ratio = size_i.max(size_j) / d.max(1e-300);
                let k = if ratio < 0.25 {
                    1
                } else if ratio < 0.6 {
                    2
                } else {
                    opts.max_receiver_samples.max(1)
                }
                .min(opts.max_receiver_samples.max(1));
                // A partly covered element may have a single open point at level k:
                // go finer rather than fall back to the representative point.
                let mut k = k;
                while k > 1 && k < MAX_K && receivers.points(i, k).len() <= 1 {
                    k += 1;
                }
                let recv_pts = receivers.points(i, k);
                if k == 1 || recv_pts.len() <= 1 {
                    let f1 = if big {
                        point_to_point(c1, ei.normal, ej.centroid, ej.normal, ej.area) * (1.0 - cut_fraction)
                    } else {
                        kernel(c1)
                    };
                    if f1 > 0.0 {
                        approx_far_q += f1;
                        let v = visibility(c1, j, q, &mut rng, &mut nrays);
                        row.push((j, f1 * v, true, (size_i / d.max(1e-300)).powi(2)));
                    }
                    continue;
                }
                let f1 = kernel(c1);
                near_f1_q += f1;
                let mut sum = 0.0;
                let mut unocc = 0.0;
                for &x in recv_pts.iter() {
                    let f = kernel(x);
                    if f <= 0.0 {
                        continue;
                    }
                    unocc += f;
                    sum += f * visibility(x, j, q, &mut rng, &mut nrays);
                }
                let m = recv_pts.len() as f64;
                // A near pair: the kernel varies over i's area faster than k × k points
                // resolve (a step where j's edge passes close above i, a log singularity
                // along an edge they share). Where i is wholly open and no twin owns part
                // of j, the unoccluded factor is taken exactly (the double contour
                // integral, so the pair is reciprocal too) and the points give only its
                // visible share, weighted by the kernel. A lamp 0.01 under a ceiling: the
                // ceiling took 0.945 of what the lamp's back sends it, and RenderPark's
                // cube (closed) let 2.95 % of its light escape (now 0.06 %); office2's
                // per-object median against the path tracer 1.80 → 1.24 %, area bias
                // −1.31 → +0.07 % (BENCHMARKS.md, "Near pairs exactly").
                let unocc_mean = if cut.is_empty() && recv_pts.len() == k * k && unocc > 0.0 {
                    let exact = super::analytic::area_factor_with(&mut exact_scratch, &ci[..ni], ei.normal, cj, ej.normal) / ei.area;
                    sum *= exact / (unocc / m);
                    exact
                } else {
                    unocc / m
                };
                near_excess += unocc_mean - f1;
                if sum > 0.0 {
                    row.push((j, sum / m, false, 0.0));
                }
            }
            if big && approx_far_q > 0.0 {
                let target = (exact_q - near_f1_q).max(0.0);
                let scale = target / approx_far_q;
                for e in row[far_start..].iter_mut().filter(|e| e.2) {
                    e.1 *= scale;
                }
            }
        }
        super::settle_far_field(row, near_excess);
        out.extend(row.iter().filter(|e| e.1 > 0.0).map(|e| (e.0, e.1)));
        nrays
    }
}

/// The convex overlaps of polygon `v` with each of `twins` (coplanar, facing the same
/// way): `v` clipped to the inside of every edge of the twin.
fn overlaps(v: &[DVec3], twins: &[u32], scene: &crate::scene::Scene, eps: f64) -> Vec<Vec<DVec3>> {
    let mut out = Vec::new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for &t in twins {
        let tp = &scene.polygons[t as usize];
        a.clear();
        a.extend_from_slice(v);
        let m = tp.vertices.len();
        for k in 0..m {
            let (p0, p1) = (tp.vertices[k], tp.vertices[(k + 1) % m]);
            let inward = tp.normal.cross(p1 - p0);
            super::geom::clip_halfspace(&a, |p| inward.dot(p - p0), 0.0, &mut b);
            std::mem::swap(&mut a, &mut b);
            if a.len() < 3 {
                break;
            }
        }
        if a.len() >= 3 && super::geom::area_3d(&a) > eps * eps {
            out.push(a.clone());
        }
    }
    out
}
