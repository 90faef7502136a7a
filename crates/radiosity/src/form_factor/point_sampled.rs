//! Point-to-polygon analytic form factors with ray-sampled visibility
//! (Wallace, Elmquist & Haines 1989, "A ray tracing algorithm for progressive radiosity").
//!
//! ```text
//! F_ij ≈ 1/m · Σ_{s=1..m} F(dA_{x_s} → A_j) · V̂(x_s, A_j)
//! ```
//!
//! `x_s` are `m = k×k` stratified points on the receiver `i` (k grows as the pair gets
//! closer: 1 when the distance exceeds four element sizes, up to `max_receiver_samples`);
//! `F(dA → A_j)` is the exact contour integral ([`super::kernel`]); `V̂` is the fraction of
//! `visibility_samples²` rays from `x_s` to stratified points of `j` that reach it. Rows of
//! a closed, unoccluded enclosure sum to one exactly (up to rounding), which is what the
//! furnace test needs. Each row draws from its own random stream (seed, row), so results
//! do not depend on the thread count.

use super::kernel::point_to_polygon;
use super::{Context, RowSource};
use crate::sampling::{rng_for, stratified};

pub(crate) struct Rows<'a> {
    ctx: &'a Context<'a>,
}

impl<'a> Rows<'a> {
    pub fn new(ctx: &'a Context<'a>) -> Self {
        Rows { ctx }
    }
}

/// Receiver points, visibility points, the patch the list is for, its facing patches.
pub(crate) type Scratch = (Vec<(f64, f64)>, Vec<(f64, f64)>, u32, Vec<u32>);

impl RowSource for Rows<'_> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        (Vec::new(), Vec::new(), u32::MAX, Vec::new())
    }

    fn row(&self, i: usize, s: &mut Scratch, row: &mut Vec<(u32, f64)>) -> u64 {
        let (recv_pts, vis_pts, cached_patch, patch_list) = s;
        let (mesh, rays, opts, eps) = (self.ctx.mesh, self.ctx.rays, self.ctx.opts, self.ctx.eps);
        let ei = &mesh.elements[i];
        let pi = ei.patch;
        if *cached_patch != pi {
            *cached_patch = pi;
            self.ctx.facing_patches(pi, patch_list);
        }
        let mut rng = rng_for(opts.seed, i as u64);
        let size_i = ei.area.sqrt();
        let mut nrays = 0u64;
        for &q in patch_list.iter() {
            let pe = mesh.patches[q as usize];
            for j in pe.first..pe.first + pe.count {
                let ej = &mesh.elements[j as usize];
                let (cj, nv) = ej.corners(&mesh.positions);
                let cj = &cj[..nv];
                // Element-level cull.
                if !cj.iter().any(|v| ei.normal.dot(*v - ei.centroid) > eps) {
                    continue;
                }
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
                stratified(k, &mut rng, recv_pts);
                let kv = opts.visibility_samples.max(1);
                let mut sum = 0.0;
                for &(u, v) in recv_pts.iter() {
                    let x = ei.point(&mesh.positions, u, v);
                    let f = point_to_polygon(x, ei.normal, cj, ej.normal);
                    if f <= 0.0 {
                        continue;
                    }
                    stratified(kv, &mut rng, vis_pts);
                    let mut seen = 0u32;
                    let mut tried = 0u32;
                    for &(a, b) in vis_pts.iter() {
                        let y = ej.point(&mesh.positions, a, b);
                        if ei.normal.dot(y - x) <= 0.0 {
                            continue;
                        }
                        tried += 1;
                        if rays.visible(x, pi, y, q) {
                            seen += 1;
                        }
                    }
                    nrays += tried as u64;
                    let vis = if tried == 0 { 1.0 } else { seen as f64 / tried as f64 };
                    sum += f * vis;
                }
                let fij = sum / recv_pts.len() as f64;
                if fij > 0.0 {
                    row.push((j, fij));
                }
            }
        }
        nrays
    }
}
