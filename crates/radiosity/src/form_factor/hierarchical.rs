//! Hierarchical links with clustering: which node pairs exchange light, and their factors
//! (Hanrahan, Salzman & Aupperle 1991, "A rapid hierarchical radiosity algorithm"; clusters
//! after Smits, Arvo & Greenberg 1994 and Sillion 1995).
//!
//! The top nodes of the element tree ([`Tree`]) holding at most 1/256 of the elements
//! (clusters or surface nodes; only surface nodes without [`Options::cluster_receivers`])
//! start linked to the root, one parallel task each, and each pair `(R, S)` is refined
//! recursively:
//!
//! - pairs that cannot exchange light are dropped: `S` inside `R`'s plane or behind it, `R`
//!   behind a surface node `S`; a node holding the other is opened;
//! - the factor `F_RS` is estimated from a few points of `R` (its receiver points or, above
//!   the leaves, the centroids of a [`Tree::frontier`]) against a frontier of up to eight
//!   nodes of `S`: exact contour integrals ([`crate::geom::kernel`]) for nearby elements,
//!   `cosθ_R · P_S(−d) / (π r²)` otherwise, with `P_S` the orientation-aware projected area
//!   of a cluster ([`crate::transport::hierarchical::Node::projected_area`]);
//! - the link is accepted when the pair is well separated, `(size_R + size_S) / r < θ`
//!   (`separation`), and its visibility, from `visibility_rays` rays between area-uniform
//!   points of the two nodes (half as many for links below the power tolerance), is not
//!   partial — or it is, but the link's power `ρ_R · F_RS · A_R · B̂_S` is below
//!   `tolerance × Σ A B̂` (BF refinement; `B̂` = emission + an ambient estimate): partial
//!   links that matter are refined, so shadow boundaries get fine links. (Widening θ for
//!   low-power links, as BF refinement also allows, was measured: up to 2× halved the links
//!   on the classroom but biased it 2.5 % dark);
//! - the factor varies across a large receiver: each link carries its gradient (a plane
//!   fitted through the estimates at the receiver's points, limited so that it cannot
//!   exceed the mean), and the push evaluates the ancestors' irradiance at each child's
//!   centroid (first-order push: row sums in the furnace within ±0.5 % instead of ±6 % at
//!   θ = 0.5);
//! - a cluster's radiosity is read as seen from the receiver
//!   ([`crate::transport::hierarchical::Link::directional`]); clusters whose elements emit
//!   unequally (a lamp and its housing) are never sources;
//! - a cluster receiver takes links from sources that emit nothing, as irradiance per unit
//!   cosine from one direction, spread to its elements by their normals
//!   ([`crate::transport::hierarchical::CLAMPED_COS`]); light from emitters always reaches
//!   surface nodes (exact cosine);
//! - otherwise the larger node (or the one that is not a leaf) is split.
//!
//! Two elements take the point-sampled factor of [`super::point_sampled`]'s kernel: the
//! contour integral at the receiver's open points (more of them when close) times the
//! visible fraction of `visibility_samples²` rays. Each task draws from its own random
//! stream, so the links do not depend on the thread count. [`predict_memory`] is checked
//! before any work.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use glam::DVec3;
use rayon::prelude::*;

use crate::accel::SceneRays;
use crate::geom::{self, kernel::point_to_polygon};
use crate::mesh::{Mesh, Receivers};
use crate::sampling::{rng_for, stratified, Rng};
use crate::transport::hierarchical::{Hierarchy, HierarchyStats, Link, Node, Tree};
use crate::{Error, Progress, Result, Rgb};

/// Link refinement settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// A link is accepted when `(size_R + size_S) / distance` is below this.
    pub separation: f64,
    /// Partially visible links carrying less than this fraction of the scene's total power
    /// are kept rather than refined (BF refinement).
    pub tolerance: f64,
    /// Rays per link above the leaves that classify its visibility (full, none, partial).
    pub visibility_rays: usize,
    /// Clusters may receive (links from non-emitting sources to groups of elements in
    /// several planes, spread to them by their normals); off: only surface nodes receive.
    pub cluster_receivers: bool,
}

/// Default [`Options::separation`].
pub const DEFAULT_SEPARATION: f64 = 0.5;
/// Default [`Options::tolerance`].
pub const DEFAULT_TOLERANCE: f64 = 1e-6;
/// Default [`Options::visibility_rays`].
pub const DEFAULT_VISIBILITY_RAYS: usize = 8;

impl Default for Options {
    fn default() -> Self {
        Options {
            separation: DEFAULT_SEPARATION,
            tolerance: DEFAULT_TOLERANCE,
            visibility_rays: DEFAULT_VISIBILITY_RAYS,
            cluster_receivers: true,
        }
    }
}

impl Options {
    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        if !(self.separation > 0.0 && self.separation <= 4.0) {
            return Err(Error::Invalid(format!("link separation must be in (0, 4], got {}", self.separation)));
        }
        if !(self.tolerance >= 0.0 && self.tolerance < 1.0) {
            return Err(Error::Invalid(format!("link tolerance must be in [0, 1), got {}", self.tolerance)));
        }
        if self.visibility_rays == 0 || self.visibility_rays > 1024 {
            return Err(Error::Invalid(format!("link visibility rays must be between 1 and 1024, got {}", self.visibility_rays)));
        }
        Ok(())
    }
}

/// Links per element assumed by [`predict_memory`]: measured 325 on the classroom
/// (12 230 elements) and 332 on 3 × 3 classrooms (60 192) at the default separation, with
/// margin; it grows slowly (as log n) and falls as 1/θ² with a larger separation.
pub const PREDICTED_LINKS_PER_ELEMENT: f64 = 400.0;

/// Peak memory of the hierarchical operator for `elements` elements at `separation`:
/// links (36 bytes each while the refinement tasks hold them, then about 16 stored: source,
/// factor and, where they exist, gradient or direction and a cluster's reading), the tree
/// (two nodes per element) and the solver's per-node buffers. Checked before any work
/// against the memory limit.
pub fn predict_memory(elements: u64, separation: f64) -> u64 {
    let links = PREDICTED_LINKS_PER_ELEMENT * (DEFAULT_SEPARATION / separation).powi(2) * elements as f64;
    let node = std::mem::size_of::<Node>() as f64 + 400.0; // node + pull/push buffers
    (links * (36.0 + 16.0) + elements as f64 * 2.0 * node) as u64
}

/// Source frontier size (far-field summary of a source node).
const SOURCE_FRONTIER: usize = 8;
/// Receiver frontier size (points of a receiver node above the leaves).
const RECEIVER_FRONTIER: usize = 4;

struct Ctx<'a> {
    tree: &'a Tree,
    mesh: &'a Mesh,
    rays: &'a SceneRays,
    receivers: &'a Receivers,
    ff: &'a super::Options,
    opts: &'a Options,
    /// Per node: area-weighted mean of max-channel reflectance.
    rho: Vec<f32>,
    /// Per node: estimated radiosity (emission + ambient), max channel.
    b_hat: Vec<f32>,
    /// Per node: its elements emit unequally (such a cluster, e.g. a lamp with a dark
    /// housing, is never a source: its radiosity depends on direction more than the
    /// first-order directional reading follows).
    emits: Vec<bool>,
    /// Per node: some element emits (its links never go to a cluster receiver).
    emits_any: Vec<bool>,
    /// Power below which a link may be coarse.
    power_eps: f64,
    /// Distance below which a point counts as on a plane.
    eps: f64,
}

#[derive(Default)]
struct Counts {
    pairs: u64,
    partial: u64,
    rays: u64,
}

/// Links every maximal surface node of `tree` against the whole tree; returns the
/// operator and the rays cast.
#[allow(clippy::too_many_arguments)]
pub fn link(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    tree: Tree,
    reflectance: &[Rgb],
    emission: &[Rgb],
    ff: &super::Options,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<(Hierarchy, u64)> {
    opts.validate()?;
    let n = mesh.len();
    let nodes = &tree.nodes;
    // B̂ = E + ambient (progressive radiosity's estimate, Cohen et al. 1988).
    let area: f64 = nodes.first().map_or(0.0, |r| r.area as f64);
    let mut rho_mean = 0.0;
    let mut emitted = 0.0;
    for k in 0..n {
        let a = (tree.area_prefix[k + 1] - tree.area_prefix[k]).max(0.0);
        let e = tree.order[k] as usize;
        rho_mean += a * reflectance[e].max_element();
        emitted += a * emission[e].max_element();
    }
    let rho_mean = if area > 0.0 { (rho_mean / area).min(0.999) } else { 0.0 };
    let ambient = if area > 0.0 { emitted / area * rho_mean / (1.0 - rho_mean) } else { 0.0 };
    let mut rho = vec![0f32; nodes.len()];
    let mut b_hat = vec![0f32; nodes.len()];
    let mut emits = vec![false; nodes.len()];
    let mut e_range = vec![(f32::INFINITY, f32::NEG_INFINITY); nodes.len()];
    for k in (0..nodes.len()).rev() {
        let nd = &nodes[k];
        if nd.is_leaf() {
            let e = tree.order[nd.first as usize] as usize;
            rho[k] = reflectance[e].max_element() as f32;
            b_hat[k] = (emission[e].max_element() + ambient) as f32;
            let x = emission[e].max_element() as f32;
            e_range[k] = (x, x);
        } else {
            let (a, b) = (nd.child[0] as usize, nd.child[1] as usize);
            let (wa, wb) = (nodes[a].area, nodes[b].area);
            let w = (wa + wb).max(f32::MIN_POSITIVE);
            rho[k] = (rho[a] * wa + rho[b] * wb) / w;
            b_hat[k] = (b_hat[a] * wa + b_hat[b] * wb) / w;
            e_range[k] = (e_range[a].0.min(e_range[b].0), e_range[a].1.max(e_range[b].1));
            emits[k] = e_range[k].1 > 1.001 * e_range[k].0;
        }
    }
    let total_power = (emitted + ambient * area).max(f64::MIN_POSITIVE);
    let (lo, hi) = geom::bounds_3d(&mesh.positions);
    let ctx = Ctx {
        tree: &tree,
        mesh,
        rays,
        receivers,
        ff,
        opts,
        rho,
        b_hat,
        emits_any: e_range.iter().map(|r| r.1 > 0.0).collect(),
        emits,
        power_eps: opts.tolerance * total_power,
        eps: 1e-7 * (hi - lo).length().max(f64::MIN_POSITIVE),
    };
    // Starting receivers: maximal surface nodes, split further so that no task holds more
    // than 1/256 of the elements (work for every thread).
    let max_count = (n / 256).max(64) as u32;
    let mut roots = Vec::new();
    let mut stack = if nodes.is_empty() { Vec::new() } else { vec![0u32] };
    while let Some(k) = stack.pop() {
        let nd = &nodes[k as usize];
        if (nd.surface || opts.cluster_receivers) && (nd.count <= max_count || nd.is_leaf()) {
            roots.push(k);
        } else {
            stack.extend(nd.child);
        }
    }
    roots.sort_unstable();
    progress.begin("links", roots.len() as u64);
    let stopped = AtomicBool::new(false);
    let total_rays = AtomicU64::new(0);
    let results: Vec<(Vec<Link>, Counts)> = roots
        .par_iter()
        .map(|&r| {
            if stopped.load(Ordering::Relaxed) || progress.should_stop() {
                stopped.store(true, Ordering::Relaxed);
                return (Vec::new(), Counts::default());
            }
            let mut links = Vec::new();
            let mut counts = Counts::default();
            ctx.refine_root(r, &mut links, &mut counts);
            total_rays.fetch_add(counts.rays, Ordering::Relaxed);
            progress.advance(1);
            (links, counts)
        })
        .collect();
    progress.end();
    if stopped.load(Ordering::Relaxed) {
        return Err(Error::Cancelled);
    }
    let mut stats = HierarchyStats::default();
    let mut parts = Vec::with_capacity(results.len());
    for (l, c) in results {
        parts.push(l);
        stats.pairs_examined += c.pairs;
        stats.partial_refined += c.partial;
    }
    drop(ctx);
    Ok((Hierarchy::from_parts(tree, parts, stats), total_rays.load(Ordering::Relaxed)))
}

/// `(size_R + size_S) / r` between the centroids; infinite when the boxes overlap (never
/// well separated).
fn separation_ratio(nr: &Node, ns: &Node) -> f64 {
    let dist = (ns.centroid - nr.centroid).length() as f64;
    let boxes_apart = nr.lo.cmpgt(ns.hi).any() || ns.lo.cmpgt(nr.hi).any();
    if boxes_apart && dist > 0.0 {
        (nr.size() + ns.size()) / dist
    } else {
        f64::INFINITY
    }
}

/// Range of the signed distance of a box's corners from a plane.
fn box_plane_range(nd: &Node, p: DVec3, n: DVec3) -> (f64, f64) {
    let (lo, hi) = (nd.lo.as_dvec3(), nd.hi.as_dvec3());
    let c = 0.5 * (lo + hi) - p;
    let h = 0.5 * (hi - lo);
    let mid = n.dot(c);
    let r = h.x * n.x.abs() + h.y * n.y.abs() + h.z * n.z.abs();
    (mid - r, mid + r)
}

impl Ctx<'_> {
    fn node(&self, k: u32) -> &Node {
        &self.tree.nodes[k as usize]
    }

    fn refine_root(&self, root: u32, links: &mut Vec<Link>, c: &mut Counts) {
        let mut rng = rng_for(self.ff.seed ^ 0x4849_4552, root as u64);
        let mut stack = vec![(root, 0u32)];
        let mut scratch = Scratch::default();
        while let Some((r, s)) = stack.pop() {
            c.pairs += 1;
            let (nr, ns) = (self.node(r), self.node(s));
            if ns.area <= 0.0 || nr.area <= 0.0 {
                continue;
            }
            if self.tree.contains(s, r) {
                // S holds R: the same plane (nothing), or a cluster to open.
                if !ns.surface {
                    stack.push((r, ns.child[0]));
                    stack.push((r, ns.child[1]));
                }
                continue;
            }
            if self.tree.contains(r, s) {
                // R holds S: a cluster to open (a surface node cannot see itself).
                if !nr.surface {
                    stack.push((nr.child[0], s));
                    stack.push((nr.child[1], s));
                }
                continue;
            }
            if !nr.surface {
                self.refine_cluster_receiver(r, s, &mut stack, links, &mut rng, &mut scratch, c);
                continue;
            }
            let (pr, n_r) = (nr.centroid.as_dvec3(), nr.normal());
            let tol = self.eps + 1e-6 * nr.size().max(ns.size());
            let (dmin, dmax) = box_plane_range(ns, pr, n_r);
            if dmax <= tol {
                continue; // behind R or in its plane
            }
            if ns.surface {
                let (_, b) = box_plane_range(nr, ns.centroid.as_dvec3(), ns.normal());
                if b <= tol {
                    continue; // R behind S
                }
            }
            let straddles = dmin < -tol;
            if (straddles || (!ns.surface && self.emits[s as usize])) && !ns.is_leaf() {
                stack.push((r, ns.child[0]));
                stack.push((r, ns.child[1]));
                continue;
            }
            if nr.is_leaf() && ns.is_leaf() {
                let i = self.tree.order[nr.first as usize];
                let j = self.tree.order[ns.first as usize];
                let f = self.leaf_factor(i, j, &mut rng, &mut scratch, c);
                if f > 0.0 {
                    links.push(Link { r, s, f: f as f32, g: [0.0; 3], dir: Link::MEAN });
                }
                continue;
            }
            let ratio = separation_ratio(nr, ns);
            if ratio < self.opts.separation {
                // Only candidate links are estimated (pairs that will be split are not).
                let (f, g) = self.estimate(r, s, ratio, &mut scratch);
                let power = f * nr.area as f64 * self.b_hat[s as usize] as f64 * self.rho[r as usize] as f64;
                if f <= 0.0 {
                    continue;
                }
                let (v, partial) = self.visibility(r, s, power <= self.power_eps, &mut rng, c);
                if !(partial && power > self.power_eps) {
                    if v > 0.0 {
                        let dir = if ns.surface {
                            Link::MEAN
                        } else {
                            Link::directional(ns, (nr.centroid - ns.centroid).as_dvec3().normalize_or_zero())
                        };
                        links.push(Link { r, s, f: (f * v) as f32, g: (g * v).as_vec3().to_array(), dir });
                    }
                    continue;
                }
                c.partial += 1;
            }
            // Split the larger node (a leaf cannot be split).
            let split_s = nr.is_leaf() || (!ns.is_leaf() && ns.size() >= nr.size());
            if split_s {
                stack.push((r, ns.child[0]));
                stack.push((r, ns.child[1]));
            } else {
                stack.push((nr.child[0], s));
                stack.push((nr.child[1], s));
            }
        }
    }

    /// One pair whose receiver `r` is a cluster: linked (irradiance per unit cosine from the
    /// direction of `s`, see [`crate::transport::hierarchical::CLAMPED_COS`]) when well
    /// separated, `s` emits nothing and visibility allows; else split.
    #[allow(clippy::too_many_arguments)]
    fn refine_cluster_receiver(
        &self,
        r: u32,
        s: u32,
        stack: &mut Vec<(u32, u32)>,
        links: &mut Vec<Link>,
        rng: &mut Rng,
        sc: &mut Scratch,
        c: &mut Counts,
    ) {
        let (nr, ns) = (self.node(r), self.node(s));
        let tol = self.eps + 1e-6 * nr.size().max(ns.size());
        if ns.surface {
            let (_, b) = box_plane_range(nr, ns.centroid.as_dvec3(), ns.normal());
            if b <= tol {
                return; // R behind S
            }
        }
        let ratio = separation_ratio(nr, ns);
        if ratio < self.opts.separation && !self.emits_any[s as usize] {
            let x = nr.centroid.as_dvec3();
            self.tree.frontier(s, SOURCE_FRONTIER, &mut sc.frontier);
            let mut k = 0.0;
            let mut dir = DVec3::ZERO;
            for &q in &sc.frontier {
                let nq = self.node(q);
                let d = nq.centroid.as_dvec3() - x;
                let r2 = d.length_squared();
                if nq.area <= 0.0 || r2 <= 0.0 {
                    continue;
                }
                let du = d / r2.sqrt();
                let kq = nq.projected_area(-du) / (std::f64::consts::PI * r2);
                k += kq;
                dir += du * kq;
            }
            let d = dir.normalize_or_zero();
            if !(k > 0.0) || d == DVec3::ZERO {
                return;
            }
            let power = k * nr.projected_area(d) * self.b_hat[s as usize] as f64 * self.rho[r as usize] as f64;
            let (v, partial) = self.visibility(r, s, power <= self.power_eps, rng, c);
            if !(partial && power > self.power_eps) {
                if v > 0.0 {
                    let read = if ns.surface { Link::MEAN } else { Link::directional(ns, -d) };
                    links.push(Link { r, s, f: (k * v).min(1.0) as f32, g: d.as_vec3().to_array(), dir: read });
                }
                return;
            }
            c.partial += 1;
        }
        if !ns.is_leaf() && ns.size() > nr.size() {
            stack.push((r, ns.child[0]));
            stack.push((r, ns.child[1]));
        } else {
            stack.push((nr.child[0], s));
            stack.push((nr.child[1], s));
        }
    }

    /// Estimated unoccluded factor from node `r` (a surface node) to node `s`, averaged
    /// over `r`, and its gradient across `r` (zero for a leaf): a least-squares plane
    /// through the estimates at the receiver points.
    fn estimate(&self, r: u32, s: u32, ratio: f64, sc: &mut Scratch) -> (f64, DVec3) {
        let nr = self.node(r);
        let n_r = nr.normal();
        sc.points.clear();
        if nr.is_leaf() {
            let e = self.tree.order[nr.first as usize] as usize;
            let k = if ratio < 0.25 { 1 } else { 2 };
            let pts = self.receivers.points(e, k);
            let w = 1.0 / pts.len().max(1) as f64;
            sc.points.extend(pts.iter().map(|&p| (p, w)));
        } else {
            self.tree.frontier(r, RECEIVER_FRONTIER, &mut sc.frontier);
            let total: f64 = sc.frontier.iter().map(|&q| self.node(q).area as f64).sum();
            for &q in &sc.frontier {
                let nq = self.node(q);
                if nq.area > 0.0 {
                    sc.points.push((nq.centroid.as_dvec3(), nq.area as f64 / total));
                }
            }
        }
        self.tree.frontier(s, SOURCE_FRONTIER, &mut sc.frontier);
        sc.values.clear();
        let mut f = 0.0;
        for &(x, w) in &sc.points {
            let mut fx = 0.0;
            for &q in &sc.frontier {
                let nq = self.node(q);
                if nq.area <= 0.0 {
                    continue;
                }
                let d = nq.centroid.as_dvec3() - x;
                let r2 = d.length_squared();
                let near = r2 <= 9.0 * nq.size() * nq.size();
                if nq.is_leaf() && near {
                    let e = &self.mesh.elements[self.tree.order[nq.first as usize] as usize];
                    let (c, nv) = e.corners(&self.mesh.positions);
                    fx += point_to_polygon(x, n_r, &c[..nv], e.normal);
                } else {
                    if r2 <= 0.0 {
                        continue;
                    }
                    let rl = r2.sqrt();
                    let cx = n_r.dot(d) / rl;
                    if cx <= 0.0 {
                        continue;
                    }
                    fx += cx * nq.projected_area(-d / rl) / (std::f64::consts::PI * r2);
                }
            }
            f += w * fx;
            sc.values.push(fx);
        }
        let mut grad = if nr.is_leaf() { DVec3::ZERO } else { plane_gradient(&sc.points, &sc.values, n_r, f) };
        // The linear term may not exceed the mean anywhere in the node (no negative or
        // runaway extrapolation from a poorly conditioned fit).
        let limit = 2.0 * f.max(0.0) / nr.size().max(f64::MIN_POSITIVE);
        let gl = grad.length();
        if gl > limit {
            grad *= limit / gl;
        }
        (f.min(1.0), grad)
    }

    /// Visible fraction between nodes `r` and `s` from area-uniform point pairs, and
    /// whether it is partial (some rays blocked, some not, or no usable pair).
    /// `minor` links (power below the tolerance, never refined) take half the rays.
    fn visibility(&self, r: u32, s: u32, minor: bool, rng: &mut Rng, c: &mut Counts) -> (f64, bool) {
        use rand::RngExt;
        let m = if minor { self.opts.visibility_rays.div_ceil(2) } else { self.opts.visibility_rays };
        let (mut valid, mut seen) = (0u32, 0u32);
        let mesh = self.mesh;
        for t in 0..m {
            let ur = (t as f64 + rng.random::<f64>()) / m as f64;
            let us = ((t * 7 + 3) % m) as f64 / m as f64 + rng.random::<f64>() / m as f64;
            let (ei, ej) = (self.tree.element_at(r, ur), self.tree.element_at(s, us));
            let (a, b) = (&mesh.elements[ei as usize], &mesh.elements[ej as usize]);
            let x = a.point(&mesh.positions, rng.random(), rng.random());
            let y = b.point(&mesh.positions, rng.random(), rng.random());
            if a.normal.dot(y - x) <= 0.0 || b.normal.dot(x - y) <= 0.0 {
                continue;
            }
            valid += 1;
            c.rays += 1;
            if self.rays.visible(x, a.patch, y, b.patch) {
                seen += 1;
            }
        }
        if valid == 0 {
            return (1.0, true);
        }
        (seen as f64 / valid as f64, seen != 0 && seen != valid)
    }

    /// Point-sampled factor between elements `i` (receiver) and `j`.
    fn leaf_factor(&self, i: u32, j: u32, rng: &mut Rng, sc: &mut Scratch, c: &mut Counts) -> f64 {
        let mesh = self.mesh;
        let (ei, ej) = (&mesh.elements[i as usize], &mesh.elements[j as usize]);
        let (cj, nv) = ej.corners(&mesh.positions);
        let cj = &cj[..nv];
        let d = (ej.centroid - ei.centroid).length();
        let size = ei.area.sqrt();
        let k = if d > 4.0 * size {
            1
        } else if d > 2.0 * size {
            2
        } else {
            self.ff.max_receiver_samples
        };
        let pts = self.receivers.points(i as usize, k);
        if pts.is_empty() {
            return 0.0;
        }
        let kv = self.ff.visibility_samples.max(1);
        let mut total = 0.0;
        for &x in pts {
            let f = point_to_polygon(x, ei.normal, cj, ej.normal);
            if f <= 0.0 {
                continue;
            }
            stratified(kv, rng, &mut sc.vis);
            let (mut valid, mut seen) = (0u32, 0u32);
            for &(u, v) in &sc.vis {
                let y = ej.point(&mesh.positions, u, v);
                if ei.normal.dot(y - x) <= self.eps {
                    continue;
                }
                valid += 1;
                if self.rays.visible(x, ei.patch, y, ej.patch) {
                    seen += 1;
                }
            }
            if valid == 0 {
                // No sample in front of x: test the centroid of the part of j in front.
                geom::clip_halfspace(cj, |p| ei.normal.dot(p - x), self.eps, &mut sc.front);
                if sc.front.len() >= 3 {
                    let y = sc.front.iter().copied().sum::<DVec3>() / sc.front.len() as f64;
                    valid = 1;
                    seen = self.rays.visible(x, ei.patch, y, ej.patch) as u32;
                }
            }
            c.rays += valid as u64;
            if valid > 0 {
                total += f * seen as f64 / valid as f64;
            }
        }
        total / pts.len() as f64
    }
}

/// The gradient in the plane with normal `n` of the values `v` at the weighted points
/// (weighted least squares about their mean `mean`; zero when they are too few or in a line
/// the gradient is taken along it).
fn plane_gradient(points: &[(DVec3, f64)], v: &[f64], n: DVec3, mean: f64) -> DVec3 {
    if points.len() < 2 {
        return DVec3::ZERO;
    }
    let c: DVec3 = points.iter().map(|(p, w)| *p * *w).sum();
    let (t, b) = crate::sampling::basis(n);
    let (mut sxx, mut sxy, mut syy, mut sxf, mut syf) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((p, w), &f) in points.iter().zip(v) {
        let d = *p - c;
        let (x, y, df) = (d.dot(t), d.dot(b), f - mean);
        sxx += w * x * x;
        sxy += w * x * y;
        syy += w * y * y;
        sxf += w * x * df;
        syf += w * y * df;
    }
    let det = sxx * syy - sxy * sxy;
    let scale = sxx + syy;
    if !(scale > 0.0) {
        return DVec3::ZERO;
    }
    if det > 1e-6 * scale * scale {
        let gx = (syy * sxf - sxy * syf) / det;
        let gy = (sxx * syf - sxy * sxf) / det;
        t * gx + b * gy
    } else {
        // Collinear points: the gradient along their line.
        let axis = (t * sxx.sqrt() + b * (sxy.signum() * syy.sqrt())).normalize_or_zero();
        let (mut sdd, mut sdf) = (0.0, 0.0);
        for ((p, w), &f) in points.iter().zip(v) {
            let d = (*p - c).dot(axis);
            sdd += w * d * d;
            sdf += w * d * (f - mean);
        }
        if sdd > 0.0 {
            axis * (sdf / sdd)
        } else {
            DVec3::ZERO
        }
    }
}


#[derive(Default)]
struct Scratch {
    values: Vec<f64>,
    points: Vec<(DVec3, f64)>,
    frontier: Vec<u32>,
    vis: Vec<(f64, f64)>,
    front: Vec<DVec3>,
}
