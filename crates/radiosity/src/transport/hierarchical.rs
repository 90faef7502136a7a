//! Hierarchical transport: links between nodes of a tree over the elements, applied by
//! pull – gather – push (Hanrahan, Salzman & Aupperle 1991; clustering after Smits, Arvo &
//! Greenberg 1994 and Sillion 1995).
//!
//! The tree ([`Tree`]) is built over the mesh's elements: *surface* nodes hold elements of
//! one plane (facing one way), *cluster* nodes anything else. A link `(R, S, f)` says that
//! every point of the receiver node `R` gathers `f · B̄_S`, with `B̄_S` the area-weighted
//! mean radiosity of the source node `S` and `f` the form factor from `R` to `S`
//! (averaged over `R`). One product `y = F·x` is
//!
//! ```text
//! pull:   B̄_S = Σ_{j ∈ S} A_j x_j / Σ_{j ∈ S} A_j          (bottom-up)
//! gather: G_R = Σ_{(R,S,f)} f · B̄_S                        (per receiver node)
//! push:   y_i = s_i · Σ_{R ∋ i} G_R                         (top-down, every ancestor)
//! ```
//!
//! so it costs O(nodes + links), not O(n²). Pushing irradiance (a value per unit area) down
//! and pulling area-weighted means up conserves power exactly: the power a link carries,
//! `f · B̄_S · A_R`, is what the receiver's leaves receive (`Σ_{i∈R} A_i · f · B̄_S`). `s_i ≤ 1` is
//! the row guard: leaves whose row sums above one are scaled to one (as
//! [`crate::form_factor::RowGuard`] does for explicit rows), by scaling what the links
//! bring and leaving the exact direct columns and traced rows alone where they fit
//! (`Hierarchy::guard_rows`). Gradients, directional
//! readings and normal-dependent pushes extrapolate, so rows summing to one could still
//! amplify a non-uniform `x` a little (the conference room in a furnace went 7 % above the
//! bound E/(1 − ρ) in two Jacobi sweeps): a directional reading is held to the largest
//! value under its source, and each `y_i` to the largest `x`, so `‖ρF‖∞ < 1` holds here too.
//! The links are computed by [`crate::form_factor::hierarchical`].

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::{SparseRows, Transport};
use crate::geom::bounds_3d;
use crate::mesh::Mesh;
use crate::Rgb;

/// Cells per side of each cube face in a cluster receiver's directional bins: irradiance
/// arriving at a cluster (from links whose receiver is a cluster) is kept per bin of
/// arrival direction as `V_b = Σ_{links in b} w · d` (per colour channel; near and far
/// links in separate bins), and a surface below the cluster with normal `n` takes
/// `Σ_b max(0, n·V_b)`, times its exposure for far links ([`Tree::set_exposure`]): the exact clamped cosine
/// `Σ w · max(0, n·d)` for every bin wholly above or below its horizon, so a face turned
/// away (the back copy of a two-sided wall, a desk's underside) takes nothing and the power
/// a link carries is what the cluster's front faces intercept. (Until 2026-12-02 a
/// second-order Legendre fit of the clamped cosine, `3/32 + t/2 + 15/32 t²`, stood here:
/// it gives 1/16 of the peak to a face turned away and 3/32 edge-on, and the two-sided
/// classroom came out 14 % brighter than with explicit rows, light created.)
pub const DIR_BIN_SIDE: usize = 4;

/// Number of directional bins (six cube faces).
pub const DIR_BINS: usize = 6 * DIR_BIN_SIDE * DIR_BIN_SIDE;

/// The directional bin of the unit direction `d` (cube map: the face of its largest
/// component, then a `DIR_BIN_SIDE²` grid on it).
#[inline]
pub fn dir_bin(d: DVec3) -> usize {
    let a = d.abs();
    let (axis, u, v, m) = if a.x >= a.y && a.x >= a.z {
        (0, d.y, d.z, d.x)
    } else if a.y >= a.z {
        (1, d.x, d.z, d.y)
    } else {
        (2, d.x, d.y, d.z)
    };
    let face = 2 * axis + (m < 0.0) as usize;
    let inv = if a.max_element() > 0.0 { 1.0 / m.abs() } else { 0.0 };
    let cell = |t: f64| (((t * inv + 1.0) * 0.5 * DIR_BIN_SIDE as f64) as usize).min(DIR_BIN_SIDE - 1);
    (face * DIR_BIN_SIDE + cell(u)) * DIR_BIN_SIDE + cell(v)
}

/// Marks "no child".
pub const NONE: u32 = u32::MAX;

/// One node of the element tree.
#[derive(Clone, Copy, Debug)]
pub struct Node {
    /// Bounding box of its elements (f32, enlarged by rounding outwards).
    pub lo: Vec3,
    /// Upper corner.
    pub hi: Vec3,
    /// Children (both [`NONE`] for a leaf, which holds one element).
    pub child: [u32; 2],
    /// Its elements are `order[first .. first + count]` ([`Tree::order`]).
    pub first: u32,
    /// Number of elements.
    pub count: u32,
    /// Open (uncovered) area.
    pub area: f32,
    /// Area-weighted centroid.
    pub centroid: Vec3,
    /// `Σ A_j n_j` over its elements (for a surface node: area × normal).
    pub n_sum: Vec3,
    /// Exposed area `Σ A_j o_j`, with `o_j` the element's exposure ([`Tree::set_exposure`]).
    pub area_x: f32,
    /// Exposed normal sum `Σ A_j o_j n_j`.
    pub n_x: Vec3,
    /// True when all its elements lie in one plane and face one way.
    pub surface: bool,
    /// Depth below the root (0).
    pub depth: u16,
}

impl Node {
    /// True for a leaf (one element).
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.child[0] == NONE
    }

    /// Length of the bounding-box diagonal.
    #[inline]
    pub fn size(&self) -> f64 {
        (self.hi - self.lo).length() as f64
    }

    /// Unit normal of a surface node (area-weighted mean of its elements' normals).
    #[inline]
    pub fn normal(&self) -> DVec3 {
        self.n_sum.as_dvec3().normalize_or_zero()
    }
}

/// A binary tree over the elements: surface nodes below cluster nodes.
#[derive(Clone, Debug, Default)]
pub struct Tree {
    /// Nodes; the root is 0 and every child comes after its parent.
    pub nodes: Vec<Node>,
    /// Elements in tree order: node `k` holds `order[first .. first + count]`.
    pub order: Vec<u32>,
    /// The leaf node of every element.
    pub leaf_of: Vec<u32>,
    /// Prefix sums of the open areas in tree order (`order.len() + 1` entries), for
    /// area-uniform sampling of a node.
    pub area_prefix: Vec<f64>,
    /// Per node: its normal distribution, `normal_bins[normal_start[k] .. normal_start[k+1]]`,
    /// the sums `Σ A_j n_j` of its elements by direction bin of `n_j` ([`dir_bin`]); empty
    /// for surface nodes, whose `n_sum` is exact. See [`Tree::projected_area`].
    pub normal_start: Vec<u32>,
    /// The bins' area-weighted normal sums.
    pub normal_bins: Vec<Vec3>,
    /// The same over the exposed areas ([`Tree::set_exposure`]).
    pub normal_bins_exposed: Vec<Vec3>,
    /// Prefix sums of the exposed areas in tree order, for sampling a cluster by them.
    pub exposed_prefix: Vec<f64>,
    /// The topmost surface nodes (surface nodes below no other), in tree order, as their
    /// normal sums `n_sum` and `n_x`: node `k`'s are `top_n[top_range[k][0] ..
    /// top_range[k][1]]`, a contiguous run (see [`Tree::front_area`]).
    pub top_n: Vec<Vec3>,
    /// The same with `n_x` (exposed).
    pub top_nx: Vec<Vec3>,
    /// Per node: its run of topmost surface nodes.
    pub top_range: Vec<[u32; 2]>,
    /// The topmost surface nodes themselves, in the same runs.
    pub top_id: Vec<u32>,
}

/// Elements of one plane share a key: normal and offset quantised.
fn plane_key(n: DVec3, c: DVec3, quantum: f64) -> (i32, i32, i32, i64) {
    let q = |v: f64| (v * 2048.0).round() as i32;
    (q(n.x), q(n.y), q(n.z), (n.dot(c) / quantum).round() as i64)
}

impl Tree {
    /// Builds the tree over `mesh`'s elements with the open `area` of each: at each node,
    /// a plane (same quantised normal and offset) that holds at least half of the node's
    /// area is split off as its own child (so a floor under furniture stays one surface
    /// node), else the elements are split at the median of the longest axis of their
    /// centroids.
    pub fn build(mesh: &Mesh, area: &[f64]) -> Tree {
        let n = mesh.len();
        let mut order: Vec<u32> = (0..n as u32).collect();
        if n == 0 {
            return Tree::default();
        }
        let (lo, hi) = bounds_3d(&mesh.positions);
        let quantum = ((hi - lo).length() * 1e-6).max(f64::MIN_POSITIVE);
        // Plane ids per element.
        let mut ids = std::collections::HashMap::new();
        let plane: Vec<u32> = mesh
            .elements
            .iter()
            .map(|e| {
                let k = plane_key(e.normal, e.centroid, quantum);
                let next = ids.len() as u32;
                *ids.entry(k).or_insert(next)
            })
            .collect();
        let mut nodes: Vec<Node> = Vec::with_capacity(2 * n);
        let blank = Node {
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
            child: [NONE; 2],
            first: 0,
            count: n as u32,
            area: 0.0,
            centroid: Vec3::ZERO,
            n_sum: Vec3::ZERO,
            area_x: 0.0,
            n_x: Vec3::ZERO,
            surface: false,
            depth: 0,
        };
        nodes.push(blank);
        let mut stack = vec![0u32];
        while let Some(k) = stack.pop() {
            let (first, count, depth) = {
                let nd = &nodes[k as usize];
                (nd.first as usize, nd.count as usize, nd.depth)
            };
            let slice = &mut order[first..first + count];
            let p0 = plane[slice[0] as usize];
            let one_plane = slice.iter().all(|&e| plane[e as usize] == p0);
            nodes[k as usize].surface = one_plane;
            if count == 1 {
                continue;
            }
            let mut mid = 0;
            if !one_plane {
                // The plane with the most area, split off when it holds half the node's
                // (sorted by plane, then runs summed: a hash map cleared per node cost
                // O(n) each at the conference room's 100k planes).
                slice.sort_unstable_by_key(|&e| (plane[e as usize], e));
                let total: f64 = slice.iter().map(|&e| mesh.elements[e as usize].area).sum();
                let (mut best, mut a, mut run, mut cur) = (u32::MAX, 0.0, 0.0, u32::MAX);
                for &e in slice.iter() {
                    let p = plane[e as usize];
                    if p != cur {
                        cur = p;
                        run = 0.0;
                    }
                    run += mesh.elements[e as usize].area;
                    if run > a {
                        a = run;
                        best = p;
                    }
                }
                // (Half with a rounding margin: the two sides of a two-sided surface hold
                // exactly half each, and summed in another order one falls just short.)
                if a >= 0.5 * total * (1.0 - 1e-9) {
                    slice.sort_by_key(|&e| plane[e as usize] != best);
                    mid = slice.iter().position(|&e| plane[e as usize] != best).unwrap_or(count);
                }
            }
            if mid == 0 || mid == count {
                let (cl, ch) = slice.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), &e| {
                    let c = mesh.elements[e as usize].centroid;
                    (l.min(c), h.max(c))
                });
                let ext = ch - cl;
                let axis = if ext.x >= ext.y && ext.x >= ext.z { 0 } else if ext.y >= ext.z { 1 } else { 2 };
                mid = count / 2;
                slice.select_nth_unstable_by(mid, |&a, &b| {
                    let (ca, cb) = (mesh.elements[a as usize].centroid[axis], mesh.elements[b as usize].centroid[axis]);
                    ca.total_cmp(&cb).then(a.cmp(&b))
                });
            }
            let c0 = nodes.len() as u32;
            for (f, c) in [(first, mid), (first + mid, count - mid)] {
                nodes.push(Node { first: f as u32, count: c as u32, depth: depth.saturating_add(1), ..blank });
            }
            nodes[k as usize].child = [c0, c0 + 1];
            stack.push(c0 + 1);
            stack.push(c0);
        }
        let mut tree = Tree { nodes, order, leaf_of: vec![NONE; n], ..Default::default() };
        tree.refit(mesh, area);
        tree
    }

    /// Recomputes every node's box, area, centroid, normal sum and normal bins, bottom-up, from the
    /// elements' `area` (e.g. their open areas once the coverage test has run; the
    /// structure, built on other areas, is kept).
    pub fn refit(&mut self, mesh: &Mesh, area: &[f64]) {
        let n = self.order.len();
        let (nodes, order) = (&mut self.nodes, &self.order);
        let mut leaf_of = vec![NONE; n];
        // Bottom-up: children come after parents.
        for k in (0..nodes.len()).rev() {
            let nd = nodes[k];
            if nd.is_leaf() {
                let ei = order[nd.first as usize] as usize;
                leaf_of[ei] = k as u32;
                let e = &mesh.elements[ei];
                let (c, nv) = e.corners(&mesh.positions);
                let (l, h) = bounds_3d(&c[..nv]);
                let a = area[ei];
                let nn = e.normal;
                let node = &mut nodes[k];
                node.lo = outward(l, false);
                node.hi = outward(h, true);
                node.area = a as f32;
                node.centroid = e.centroid.as_vec3();
                node.n_sum = (nn * a).as_vec3();
                node.area_x = node.area;
                node.n_x = node.n_sum;
            } else {
                let (a, b) = (nodes[nd.child[0] as usize], nodes[nd.child[1] as usize]);
                let area = a.area + b.area;
                let node = &mut nodes[k];
                node.lo = a.lo.min(b.lo);
                node.hi = a.hi.max(b.hi);
                node.area = area;
                node.centroid = if area > 0.0 {
                    (a.centroid * a.area + b.centroid * b.area) / area
                } else {
                    0.5 * (a.centroid + b.centroid)
                };
                node.n_sum = a.n_sum + b.n_sum;
                node.area_x = area;
                node.n_x = node.n_sum;
            }
        }
        let mut area_prefix = Vec::with_capacity(n + 1);
        area_prefix.push(0.0);
        let mut acc = 0.0;
        for &e in order.iter() {
            acc += area[e as usize];
            area_prefix.push(acc);
        }
        self.leaf_of = leaf_of;
        self.exposed_prefix = area_prefix.clone();
        self.area_prefix = area_prefix;
        self.bin_normals();
    }

    /// Sets every element's *exposure* `o_j ∈ [0, 1]` (indexed by element): the share of
    /// its hemisphere that reaches beyond its own neighbourhood (see
    /// [`crate::form_factor::hierarchical`]). Clusters are seen, and receive, through their
    /// exposed area `Σ A_j o_j`: a face inside a closed slab, or the back copy of a wall
    /// facing into a cavity, faces a far node but neither sends to it nor receives from it.
    /// Surface nodes' own factors are unchanged (their visibility comes from rays).
    pub fn set_exposure(&mut self, exposure: &[f32]) {
        let nodes = &mut self.nodes;
        for k in (0..nodes.len()).rev() {
            let nd = nodes[k];
            if nd.is_leaf() {
                let o = exposure[self.order[nd.first as usize] as usize].clamp(0.0, 1.0);
                nodes[k].area_x = nd.area * o;
                nodes[k].n_x = nd.n_sum * o;
            } else {
                let (a, b) = (nodes[nd.child[0] as usize], nodes[nd.child[1] as usize]);
                nodes[k].area_x = a.area_x + b.area_x;
                nodes[k].n_x = a.n_x + b.n_x;
            }
        }
        let mut acc = 0.0;
        let mut prefix = Vec::with_capacity(self.order.len() + 1);
        prefix.push(0.0);
        for &e in &self.order {
            let leaf = &self.nodes[self.leaf_of[e as usize] as usize];
            acc += leaf.area_x as f64;
            prefix.push(acc);
        }
        self.exposed_prefix = prefix;
        self.bin_normals();
    }

    /// The exposure of node `k`: its exposed share of its open area (1 without exposure).
    #[inline]
    pub fn exposure(&self, k: u32) -> f64 {
        let nd = &self.nodes[k as usize];
        if nd.area > 0.0 {
            (nd.area_x / nd.area) as f64
        } else {
            0.0
        }
    }

    /// The normal distribution of every cluster node (see [`Tree::normal_bins`]), bottom-up:
    /// a surface child is one entry, a cluster child its own list.
    fn bin_normals(&mut self) {
        let nodes = &self.nodes;
        let m = nodes.len();
        let mut lists: Vec<Vec<(u8, DVec3, DVec3)>> = vec![Vec::new(); m];
        let mut dense = [(DVec3::ZERO, DVec3::ZERO); DIR_BINS];
        let mut used: Vec<u8> = Vec::with_capacity(DIR_BINS);
        for k in (0..m).rev() {
            let nd = &nodes[k];
            if nd.surface {
                continue;
            }
            used.clear();
            for c in nd.child {
                let cn = &nodes[c as usize];
                let mut add = |b: u8, v: DVec3, x: DVec3| {
                    used.push(b);
                    dense[b as usize].0 += v;
                    dense[b as usize].1 += x;
                };
                if cn.surface {
                    let n = cn.n_sum.as_dvec3();
                    add(dir_bin(n.normalize_or_zero()) as u8, n, cn.n_x.as_dvec3());
                } else {
                    for &(b, v, x) in &lists[c as usize] {
                        add(b, v, x);
                    }
                }
            }
            used.sort_unstable();
            used.dedup();
            lists[k] = used
                .iter()
                .map(|&b| {
                    let (v, x) = std::mem::take(&mut dense[b as usize]);
                    (b, v, x)
                })
                .collect();
        }
        let mut start = Vec::with_capacity(m + 1);
        start.push(0u32);
        let (mut bins, mut exposed) = (Vec::new(), Vec::new());
        for l in &lists {
            bins.extend(l.iter().map(|&(_, v, _)| v.as_vec3()));
            exposed.extend(l.iter().map(|&(_, _, x)| x.as_vec3()));
            start.push(bins.len() as u32);
        }
        self.normal_start = start;
        self.normal_bins = bins;
        self.normal_bins_exposed = exposed;
        self.index_surfaces();
    }

    /// [`Tree::top_n`], [`Tree::top_nx`] and [`Tree::top_range`]: the topmost surface nodes
    /// in tree order (depth first, first child first, so every node's lie in one run).
    fn index_surfaces(&mut self) {
        let nodes = &self.nodes;
        let (mut top_n, mut top_nx, mut top_id) = (Vec::new(), Vec::new(), Vec::new());
        let mut range = vec![[0u32; 2]; nodes.len()];
        let mut stack = if nodes.is_empty() { Vec::new() } else { vec![0u32] };
        while let Some(k) = stack.pop() {
            let nd = &nodes[k as usize];
            if nd.surface {
                let i = top_n.len() as u32;
                range[k as usize] = [i, i + 1];
                top_n.push(nd.n_sum);
                top_nx.push(nd.n_x);
                top_id.push(k);
            } else {
                stack.extend(nd.child.iter().rev().filter(|&&c| c != NONE));
            }
        }
        // Clusters, bottom-up (children come after parents): the union of their children's
        // runs, which are adjacent. Surface nodes below a topmost one keep their own run
        // (front_area reads a surface node directly).
        for k in (0..nodes.len()).rev() {
            let nd = &nodes[k];
            if nd.surface {
                continue;
            }
            let mut r = [u32::MAX, 0];
            for c in nd.child.into_iter().filter(|&c| c != NONE) {
                let rc = range[c as usize];
                r = [r[0].min(rc[0]), r[1].max(rc[1])];
            }
            range[k] = if r[0] <= r[1] { r } else { [0, 0] };
        }
        self.top_n = top_n;
        self.top_nx = top_nx;
        self.top_id = top_id;
        self.top_range = range;
    }

    /// `Σ_j A_j max(0, n_j·d)`: the projected area of node `k`'s front faces towards the unit
    /// direction `d`. Exact for a surface node; for a cluster the sum over its normal bins,
    /// `Σ_b max(0, m_b·d)`, exact unless a bin's normals straddle `d`'s horizon. (The
    /// estimate it replaced, the Cauchy–Schwarz bound from the first two normal moments,
    /// overstated a desk's top by ~20 % where its legs and two-sided copies mix normals.)
    /// [`Tree::front_area`] is the exact sum.
    /// With `exposed`, a cluster's exposed faces only ([`Tree::set_exposure`]; a surface
    /// node's projected area is its own either way).
    #[inline]
    pub fn projected_area(&self, k: u32, d: DVec3, exposed: bool) -> f64 {
        let nd = &self.nodes[k as usize];
        if nd.surface {
            return nd.n_sum.as_dvec3().dot(d).max(0.0);
        }
        let (a, b) = (self.normal_start[k as usize] as usize, self.normal_start[k as usize + 1] as usize);
        let bins = if exposed { &self.normal_bins_exposed } else { &self.normal_bins };
        front_sum(&bins[a..b], d)
    }

    /// True when node `a` holds every element of node `b` (`b` is `a` or below it).
    #[inline]
    pub fn contains(&self, a: u32, b: u32) -> bool {
        let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
        na.first <= nb.first && nb.first + nb.count <= na.first + na.count
    }

    /// `Σ A_j max(0, n_j·d)` over the elements of node `k` (open areas), exactly: the area
    /// its front faces present to light arriving from the unit direction `d`, summed over
    /// the topmost surface nodes below `k` (each one plane, so exact; what the push of a
    /// cluster receiver hands out per unit of a link from `d`). [`Tree::projected_area`] is
    /// the constant-time estimate.
    pub fn front_area(&self, k: u32, d: DVec3, exposed: bool) -> f64 {
        let nd = &self.nodes[k as usize];
        if nd.surface {
            return if exposed { nd.n_x } else { nd.n_sum }.as_dvec3().dot(d).max(0.0);
        }
        // The topmost surface nodes below k, one contiguous run.
        let [a, b] = self.top_range[k as usize];
        let run = if exposed { &self.top_nx[a as usize..b as usize] } else { &self.top_n[a as usize..b as usize] };
        front_sum(run, d)
    }

    /// The element at area fraction `u ∈ [0, 1)` of node `k` (area-uniform choice).
    #[inline]
    pub fn element_at(&self, k: u32, u: f64) -> u32 {
        self.order[self.slot_at(k, u)]
    }

    /// [`Tree::element_at`] as a position in [`Tree::order`] (for data kept in tree order).
    #[inline]
    pub fn slot_at(&self, k: u32, u: f64) -> usize {
        self.slot_by(&self.area_prefix, k, u)
    }

    /// The position in tree order at fraction `u` of node `k`'s share of the prefix sums `p`.
    #[inline]
    pub(crate) fn slot_by(&self, p: &[f64], k: u32, u: f64) -> usize {
        let nd = &self.nodes[k as usize];
        let (a, b) = (nd.first as usize, (nd.first + nd.count) as usize);
        let target = p[a] + u * (p[b] - p[a]);
        let slot = p[a + 1..=b].partition_point(|&x| x <= target);
        (a + slot).min(b - 1)
    }

    /// The element at fraction `u ∈ [0, 1)` of node `k`'s exposed area (area-uniform for a
    /// surface node; falls back to the open area where nothing is exposed).
    #[inline]
    pub fn element_at_exposed(&self, k: u32, u: f64) -> u32 {
        self.order[self.slot_at_exposed(k, u)]
    }

    /// [`Tree::element_at_exposed`] as a position in [`Tree::order`].
    #[inline]
    pub fn slot_at_exposed(&self, k: u32, u: f64) -> usize {
        let nd = &self.nodes[k as usize];
        if nd.surface || !(nd.area_x > 0.0) {
            return self.slot_at(k, u);
        }
        self.slot_by(&self.exposed_prefix, k, u)
    }

    /// Up to `k` nodes that cover node `node` (descending into the largest first): a
    /// summary of its shape for the far field.
    pub fn frontier(&self, node: u32, k: usize, out: &mut Vec<u32>) {
        out.clear();
        out.push(node);
        while out.len() < k {
            let Some((pos, _)) = out
                .iter()
                .enumerate()
                .filter(|(_, &m)| !self.nodes[m as usize].is_leaf())
                .max_by(|a, b| self.nodes[*a.1 as usize].area.total_cmp(&self.nodes[*b.1 as usize].area))
            else {
                break;
            };
            let c = self.nodes[out[pos] as usize].child;
            out[pos] = c[0];
            out.push(c[1]);
        }
    }
}

/// `Σ max(0, m·d)` over area-weighted normals `m`: the area they present to the direction
/// `d`. Four running sums instead of one, so that the additions do not wait on each other
/// (runs of a cluster's faces are long on curved models: on Sponza this sum and
/// [`Tree::projected_area`]'s took 6 % of a render with one).
#[inline]
fn front_sum(run: &[Vec3], d: DVec3) -> f64 {
    let term = |m: &Vec3| m.as_dvec3().dot(d).max(0.0);
    let mut acc = [0.0f64; 4];
    let mut quads = run.chunks_exact(4);
    for q in &mut quads {
        for (a, m) in acc.iter_mut().zip(q) {
            *a += term(m);
        }
    }
    let rest: f64 = quads.remainder().iter().map(term).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + rest
}

/// Rounds an f64 box corner to f32 outwards.
fn outward(v: DVec3, up: bool) -> Vec3 {
    let f = |x: f64| {
        let y = x as f32;
        if up && (y as f64) < x {
            y.next_up()
        } else if !up && (y as f64) > x {
            y.next_down()
        } else {
            y
        }
    };
    Vec3::new(f(v.x), f(v.y), f(v.z))
}

/// What the hierarchy holds, for the report.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct HierarchyStats {
    /// Nodes of the tree.
    pub nodes: u64,
    /// Surface nodes (one plane) among them.
    pub surface_nodes: u64,
    /// Links.
    pub links: u64,
    /// Links whose source is a cluster (several planes).
    pub cluster_links: u64,
    /// Links whose receiver is a cluster (irradiance by direction, see [`DIR_BIN_SIDE`]).
    pub cluster_receiver_links: u64,
    /// Links between two leaves (single elements).
    pub leaf_links: u64,
    /// Links received per tree depth (index = depth).
    pub links_per_depth: Vec<u64>,
    /// Node pairs the refinement examined.
    pub pairs_examined: u64,
    /// Node pairs subdivided because their visibility was partial.
    pub partial_refined: u64,
    /// Of those, pairs that every visibility ray found hidden and more rays found partly
    /// visible (light through a slit; `crate::form_factor::hierarchical::GLIMPSE`).
    pub glimpsed: u64,
    /// Links between two nodes at the minimum size that are not well separated (their
    /// factor integrated point by point, see [`crate::form_factor::hierarchical`]).
    pub terminal_links: u64,
    /// Pairs linked above the minimum size by BF refinement (not well separated, carrying
    /// at most the link tolerance; [`crate::form_factor::hierarchical::Options::coarse_size`]),
    /// counted when integrated like `terminal_links` (a hidden pair stores no link).
    pub coarse_links: u64,
    /// Leaves whose row (links, direct columns, traced row) summed above one (+ 1e-3): the
    /// guard scales what their links bring so that the row sums to one (the direct columns
    /// and traced row too where they alone exceed one).
    pub rows_scaled: u64,
    /// Of those, the leaves whose row summed to at most one before the closure fit: the
    /// fit lifted their group towards its measured closure and them past one. The others
    /// overcount by their links alone (coincident, touching or interpenetrating parts).
    pub rows_lifted: u64,
    /// The largest raw leaf row sum.
    pub max_row_sum: f64,
    /// The element with that sum.
    pub worst_row: Option<u64>,
    /// Bytes held by the tree and the links.
    pub memory_bytes: u64,
    /// The run's peak resident memory as predicted before the coverage test and the links
    /// ([`crate::form_factor::hierarchical::predict_peak`]; 0 where nothing predicted it).
    pub predicted_peak_bytes: u64,
    /// Of that, what the process held already when predicting.
    pub resident_before_bytes: u64,
    /// Emitting elements whose light reaches every element through exact factors instead
    /// of links (0: emitters are sources in the hierarchy).
    pub direct_emitters: u64,
    /// Non-zero factors to them.
    pub direct_entries: u64,
    /// Rays the direct columns cast (shadow rays and the culling of hidden emitter
    /// groups, [`crate::form_factor::hierarchical`]).
    pub direct_rays: u64,
    /// The minimum node size links were refined to (scene units; 0: the elements).
    pub min_size: f64,
    /// Nodes that links can reach at that size (the root and every child of a node
    /// larger than it).
    pub link_nodes: u64,
    /// Rays per element that measured the closure the rows are fitted to (0: none).
    pub closure_rays: u64,
    /// Area-weighted mean of the closure's scale on what the links bring (1: the links
    /// alone already closed the rows).
    pub closure_mean_scale: f64,
    /// Elements whose links were scaled (their group's row sum lay outside the closure's
    /// confidence interval).
    pub closure_fitted: u64,
    /// Elements whose links fell far short of their closure and gather by rays instead
    /// ([`Hierarchy::set_ray_rows`]).
    pub ray_rows: u64,
    /// Entries of those rows.
    pub ray_row_entries: u64,
}

/// The measured closure of every element and the groups it is fitted over
/// ([`Hierarchy::from_parts`]).
#[derive(Clone, Debug, Default)]
pub struct Closure {
    /// Per element: the fraction of its closure rays whose first hit is a front face (NaN
    /// for an element with no open area).
    pub fraction: Vec<f32>,
    /// Rays per element.
    pub rays: u32,
    /// Per element: its group (e.g. the smallest node that links reach holding it; its
    /// elements share one scale, fitted to their pooled rays).
    pub group: Vec<u32>,
}

/// Standard deviations of the closure's confidence interval: a group's row sum inside it is
/// left alone.
pub const CLOSURE_Z: f64 = 2.0;

/// The Wilson score interval for a fraction `p` of `n` trials at `z` standard deviations.
pub fn wilson(p: f64, n: f64, z: f64) -> (f64, f64) {
    let z2 = z * z;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = z / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    (centre - half, centre + half)
}

/// Prior probability that an element whose `m` closure rays all met a surface lies in a
/// closed neighbourhood (closure 1) rather than being like the rest of its group (closure
/// `c_g`, the group's pooled fraction). Its row is fitted to the expected closure given
/// the rays, `c_g + (1 − c_g)·w` with `w = π / (π + (1 − π)·c_g^m)`: an element in a
/// crevice of an open group (`c_g^m` tiny) to one, an element of a group that is nearly
/// closed anyway to little more than `c_g`. Fitting every such row to one made an open
/// corridor let out 12 % less light than the rows (2 % now;
/// `tests/hierarchical.rs an_open_corridor_lets_out_what_the_rows_let_out`), the
/// conference −0.68 % escaped (−0.07 % now), the classroom at link size 2.72 −1.39 %
/// (+0.15 %; stochastic Jacobi loses 3.58 %).
pub const CLOSED_PRIOR: f64 = 0.1;

/// The range of the closure's scale on an element's links (see [`Hierarchy::from_parts`]):
/// beyond it the links are too far off for one factor to mend, and are left to the guard.
pub const CLOSURE_SCALE: (f64, f64) = (0.5, 2.0);

/// A face that a cluster receiver's link must not light: the topmost surface node `c` below
/// the link's receiver lies wholly in the plane of the link's surface source `s` or behind
/// it, or `s` (a surface or a cluster) lies wholly in `c`'s plane or behind it, so it sees
/// nothing of `s`, but the walk down the cluster would hand it `coef` times the link's
/// reading of `s` by its normal alone (see [`DIR_BIN_SIDE`]); the product takes that back.
/// The back copy of a two-sided floor under the chairs on it, lit through their cluster by
/// the next floor patch, is the case (BENCHMARKS.md, "Seventeenth round").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exclusion {
    /// The face (a topmost surface node).
    pub c: u32,
    /// The link's source.
    pub s: u32,
    /// What the walk hands the face per unit of the source's reading: the link's factor
    /// times `max(0, n_c·d)`, times the face's exposure for a far link.
    pub coef: f32,
    /// How the link reads its source ([`Link::dir`]).
    pub dir: [f32; 4],
    /// Whether the link is a near one ([`Link::near`]).
    pub near: bool,
}

/// One link: receiver node `r` gathers `f · B̄_s`, plus `g · (x − c_r)` at a point `x` of
/// it (`c_r` its centroid): the factor's first-order change across a large receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    /// Receiver node.
    pub r: u32,
    /// Source node.
    pub s: u32,
    /// Form factor from the receiver to the source, averaged over the receiver.
    pub f: f32,
    /// Its gradient across the receiver (per scene unit).
    pub g: [f32; 3],
    /// How the source's radiosity is read: `α · B̄_s + β · N_B(s)` with `N_B = Σ A_j B_j n_j`
    /// ([`Link::directional`] for a cluster seen from one direction; `[1, 0, 0, 0]`, the
    /// plain mean, for a surface node). Stored only for cluster sources, and `g` only for
    /// receivers above the leaves: the operator keeps about 16 bytes per link.
    pub dir: [f32; 4],
    /// A near-field link (two nodes at the minimum size, not well separated, its factor
    /// integrated with rays): clusters send and receive through all their faces. A far
    /// link reaches them through their exposed faces ([`Tree::set_exposure`]). Stored as
    /// the sign of the factor.
    pub near: bool,
}

impl Link {
    /// The plain area-weighted mean of the source.
    pub const MEAN: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

    /// The mean radiosity of cluster `s`'s front faces as seen from the unit direction `d`
    /// (from the cluster towards the receiver), weighted by their projected area:
    /// `Σ A_j max(0, n_j·d) B_j / Σ A_j max(0, n_j·d)` with `max(0, c) = ½|c| + ½c`, the
    /// `|c|` part taken at the mean radiosity and the `c` part exact through `N_B`. A desk
    /// seen from the ceiling then gives its lit top's radiosity, not the mean of top and
    /// dark underside (the classroom ceiling was 27 % dark without it). `p` is its projected
    /// area towards `d` ([`Tree::projected_area`]).
    pub fn directional(s: &Node, p: f64, d: DVec3, near: bool) -> [f32; 4] {
        let (area, n) = if near { (s.area, s.n_sum) } else { (s.area_x, s.n_x) };
        // Seen almost edge-on the reading divides by a vanishing projected area: rounding
        // of the f32 coefficients would dominate (raw row sums of 2 000 in the classroom).
        // Such links carry almost nothing (their factor has the same projected area).
        if !(p > 0.01 * area as f64) {
            return Link::MEAN;
        }
        let half_abs = p - 0.5 * n.as_dvec3().dot(d);
        let b = 0.5 * d / p;
        [(half_abs / p) as f32, b.x as f32, b.y as f32, b.z as f32]
    }
}

/// The hierarchical operator: the tree, links stored by receiver node, and the row guard.
#[derive(Clone, Debug, Default)]
pub struct Hierarchy {
    /// The element tree.
    pub tree: Tree,
    /// Links of receiver node `k`: `link_start[k] .. link_start[k+1]`.
    link_start: Vec<u32>,
    /// Each link's source as a *slot*: an index into `slot_node`, the nodes that some
    /// link or exclusion reads, in node order. A product reads its sources from a table
    /// of readings per slot ([`Reading`]), two cache lines each, instead of five arrays
    /// over every node (Sponza: 165 525 slots of 494 127 nodes, 28 links a slot; a
    /// product on one thread 0.60–0.72 → 0.49 s; the conference room: 367 948 of 1 388 325,
    /// two links a slot, a product 0.35 → 0.33 s).
    link_src: Vec<u32>,
    slot_node: Vec<u32>,
    /// The slot of each exclusion's source.
    ex_slot: Vec<u32>,
    link_f: Vec<f32>,
    /// The vectors of the links of non-leaf receivers (gradient, or a cluster receiver's
    /// direction): node `k`'s at `g_base[k] ..` in its link order; [`NONE`] for leaves,
    /// whose links have none.
    link_g: Vec<[f32; 3]>,
    g_base: Vec<u32>,
    /// The directional readings of links from cluster sources, which come last in each
    /// receiver's list (`cluster_count[k]` of them): at `dir_base[k] ..`.
    link_dir: Vec<[f32; 4]>,
    dir_base: Vec<u32>,
    cluster_count: Vec<u32>,
    /// Per element: scale applied to what its links bring, fitting the row to the measured
    /// closure (1 without one; see [`Hierarchy::from_parts`]).
    link_scale: Vec<f32>,
    /// Per element: what its links bring for `x = 1` before any scale (no direct columns,
    /// no traced row). The closure fit and every row sum are read from it: one product
    /// instead of five on a large scene (each a walk over every link). Taken in
    /// [`Hierarchy::from_parts`]: the tree (areas, normals, exposure) must not change after.
    link_ones: Vec<f64>,
    /// The closure the links were fitted to, kept to fit them again without the elements
    /// whose rows are traced ([`Hierarchy::set_ray_rows`]).
    closure: Option<Closure>,
    /// Per element: the row guard's scale on what its links bring (1 unless its row summed
    /// above 1; see [`Hierarchy::guard_rows`]).
    scale: Vec<f32>,
    /// Per element: the row guard's scale on its direct columns and traced row (1 unless
    /// those alone sum above 1).
    fixed_scale: Vec<f32>,
    /// Exact factors from every element to the emitting elements, when emitted light
    /// travels outside the links (see [`crate::form_factor::hierarchical::Options::direct_columns`]).
    direct: Option<SparseRows>,
    /// Ray-traced rows of the elements that the links serve badly (see
    /// [`Hierarchy::set_ray_rows`]): their links are switched off.
    ray_rows: Option<SparseRows>,
    /// Faces that cluster receivers' links must not light ([`Exclusion`]), sorted by face.
    exclusions: Vec<Exclusion>,
    /// What it holds.
    pub stats: HierarchyStats,
    /// A product's per-node buffers, kept for the next one ([`Buffers`]).
    buffers: BufferCell,
}

/// The per-node buffers of one product `F·x` (pull values and gathered irradiance): on the
/// conference room 1.4 M nodes × ~310 bytes. Allocated afresh for each of a solve's
/// products, their pages were faulted in and zeroed every time (a tenth of the conference
/// room's solve in `perf`); kept between products they are written in place.
#[derive(Default)]
struct Buffers {
    /// Readings per source slot (see `Hierarchy::link_src`): over all faces, and over
    /// the exposed ones.
    near: Vec<Reading>,
    far: Vec<Reading>,
    mean: Vec<Rgb>,
    nb: Vec<[DVec3; 3]>,
    nbx: Vec<[DVec3; 3]>,
    sx: Vec<Rgb>,
    hi: Vec<Rgb>,
    g: Vec<(Rgb, [DVec3; 3])>,
}

/// Where [`Buffers`] wait between products: taken by a product and put back after it (a
/// product running beside another allocates its own). A clone starts empty.
#[derive(Default)]
struct BufferCell(std::sync::Mutex<Option<Buffers>>);

impl Clone for BufferCell {
    fn clone(&self) -> Self {
        BufferCell::default()
    }
}

impl std::fmt::Debug for BufferCell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("BufferCell")
    }
}

/// How many links ahead a product starts loading a link's source
/// ([`Hierarchy::prefetch_source`]). Sponza's products, one process alternating with and
/// without (BENCHMARKS.md, "Twelfth round"): median 0.494 → 0.419 s on two threads, 1.28
/// → 0.95 s on one (8 ahead: 0.533 → 0.423 s); the classroom's 0.043 → 0.039 s; the
/// conference room's unchanged (0.224 s).
const PREFETCH_AHEAD: usize = 16;

/// Elements below which [`Hierarchy::walk_clusters`] stays on one thread.
const PARALLEL_WALK: usize = 4096;

/// What a link reads of its source during one product: the source's mean radiosity, its
/// `Σ A_j B_j n_j` per channel and the largest radiosity below it. Over all its faces
/// (near links) or, for far links, over its exposed faces: mean `Σ A_j o_j B_j / Σ A_j
/// o_j`, `Σ A_j o_j B_j n_j`. Two cache lines, one table per kind, one entry per source
/// slot: a link's read touches two adjacent lines of a table over the sources only,
/// instead of five arrays and the node over every node.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
struct Reading {
    mean: Rgb,
    n: [DVec3; 3],
    hi: Rgb,
}

/// What links read from their sources during one product, per source slot.
struct Sources<'a> {
    near: &'a [Reading],
    far: &'a [Reading],
}

impl Hierarchy {
    /// Assembles the operator from the tree and links (any order), measures every leaf's
    /// row sum over its own and its ancestors' links and scales rows above one to one.
    pub fn new(tree: Tree, links: Vec<Link>, stats: HierarchyStats) -> Hierarchy {
        Hierarchy::from_parts(tree, vec![links], Vec::new(), None, None, stats)
    }

    /// As [`Hierarchy::new`] from several lists of links (one per refinement task), and the
    /// faces their cluster receivers must not light (`exclusions`), each list
    /// dropped as soon as it is stored: links are placed by a counting sort on the receiver,
    /// so the peak is the stored links plus one task's list, not three copies of all.
    /// `direct` holds the factors to the emitting elements when emitted light does not go
    /// through the links (rows indexed by element, like the operator's). `closure`, when
    /// given, is every element's measured closure (the fraction of its cosine-weighted
    /// hemisphere that meets a front face, by rays): links estimated between nodes that
    /// touch are biased (low beside a shared edge, where the kernel is singular), the
    /// closure is not. Per group of elements, the area-weighted row sum is compared with the
    /// pooled closure's Wilson interval at [`CLOSURE_Z`]; outside it, what the group's links
    /// bring is scaled to the nearest bound, `s = (c − Σ D) / Σ links`, within
    /// [`CLOSURE_SCALE`]. A group's rows are thus fitted only where the rays show a
    /// deviation, and an element alone with a handful of rays is left as it is.
    pub fn from_parts(
        tree: Tree,
        mut parts: Vec<Vec<Link>>,
        exclusions: Vec<Exclusion>,
        direct: Option<SparseRows>,
        closure: Option<Closure>,
        mut stats: HierarchyStats,
    ) -> Hierarchy {
        let m = tree.nodes.len();
        let total: usize = parts.iter().map(Vec::len).sum();
        let mut link_start = vec![0u32; m + 1];
        let mut cluster_count = vec![0u32; m];
        let depth = tree.nodes.iter().map(|n| n.depth as usize).max().unwrap_or(0);
        stats.links_per_depth = vec![0; depth + 1];
        for l in parts.iter().flatten() {
            link_start[l.r as usize + 1] += 1;
            cluster_count[l.r as usize] += !tree.nodes[l.s as usize].surface as u32;
            let (nr, ns) = (&tree.nodes[l.r as usize], &tree.nodes[l.s as usize]);
            stats.links_per_depth[nr.depth as usize] += 1;
            stats.cluster_links += !ns.surface as u64;
            stats.cluster_receiver_links += !nr.surface as u64;
            stats.leaf_links += (nr.is_leaf() && ns.is_leaf()) as u64;
        }
        for k in 0..m {
            link_start[k + 1] += link_start[k];
        }
        // Extras only where they exist: vectors for non-leaf receivers, readings for
        // cluster sources (placed last in each receiver's list).
        let (mut g_base, mut dir_base) = (vec![NONE; m], vec![0u32; m]);
        let (mut ng, mut nd) = (0usize, 0usize);
        for k in 0..m {
            let count = (link_start[k + 1] - link_start[k]) as usize;
            if !tree.nodes[k].is_leaf() && count > 0 {
                g_base[k] = ng as u32;
                ng += count;
            }
            dir_base[k] = nd as u32;
            nd += cluster_count[k] as usize;
        }
        let mut fill_surface: Vec<u32> = link_start[..m].to_vec();
        let mut fill_cluster: Vec<u32> = (0..m).map(|k| link_start[k + 1] - cluster_count[k]).collect();
        let mut link_src = vec![0u32; total];
        let mut link_f = vec![0f32; total];
        let mut link_g = vec![[0f32; 3]; ng];
        let mut link_dir = vec![[0f32; 4]; nd];
        for part in parts.iter_mut() {
            for l in part.drain(..) {
                let k = l.r as usize;
                let cluster_source = !tree.nodes[l.s as usize].surface;
                let fill = if cluster_source { &mut fill_cluster[k] } else { &mut fill_surface[k] };
                let p = *fill as usize;
                *fill += 1;
                link_src[p] = l.s;
                link_f[p] = if l.near { -l.f } else { l.f };
                if g_base[k] != NONE {
                    link_g[g_base[k] as usize + p - link_start[k] as usize] = l.g;
                }
                if cluster_source {
                    let first = (link_start[k + 1] - cluster_count[k]) as usize;
                    link_dir[dir_base[k] as usize + p - first] = l.dir;
                }
            }
            *part = Vec::new();
        }
        // Sources to slots (see `link_src`), exclusions' sources included.
        let mut slot_of = vec![NONE; m];
        for &sn in &link_src {
            slot_of[sn as usize] = 0;
        }
        for e in &exclusions {
            slot_of[e.s as usize] = 0;
        }
        let mut slot_node = Vec::new();
        for (k, sl) in slot_of.iter_mut().enumerate() {
            if *sl != NONE {
                *sl = slot_node.len() as u32;
                slot_node.push(k as u32);
            }
        }
        for sn in link_src.iter_mut() {
            *sn = slot_of[*sn as usize];
        }
        stats.links = total as u64;
        stats.nodes = m as u64;
        stats.surface_nodes = tree.nodes.iter().filter(|n| n.surface).count() as u64;
        let n = tree.order.len();
        let mut h = Hierarchy {
            tree,
            link_start,
            link_src,
            slot_node,
            ex_slot: Vec::new(),
            link_f,
            link_g,
            g_base,
            link_dir,
            dir_base,
            cluster_count,
            link_scale: vec![1.0; n],
            link_ones: Vec::new(),
            closure: None,
            scale: vec![1.0; n],
            fixed_scale: vec![1.0; n],
            direct,
            ray_rows: None,
            exclusions: {
                let mut ex = exclusions;
                ex.sort_by_key(|e| (e.c, e.s));
                ex
            },
            stats,
            buffers: BufferCell::default(),
        };
        h.ex_slot = h.exclusions.iter().map(|e| slot_of[e.s as usize]).collect();
        drop(slot_of);
        h.stats.direct_entries = h.direct.as_ref().map_or(0, |d| d.nnz() as u64);
        // Every scale is still 1 and no row is traced: the links alone.
        let ones = vec![Rgb::ONE; n];
        let mut y = vec![Rgb::ZERO; n];
        h.apply(&ones, &mut y, false, false);
        h.link_ones = y.iter().map(|v| v.x).collect();
        if let Some(c) = closure {
            h.fit_closure(&c, &[]);
            h.closure = Some(c);
        }
        h.guard_rows();
        h
    }

    /// Gives the elements in `rows` (element, its factors to elements) rows traced by rays
    /// in place of their links: elements in crevices and behind other parts of a cluster
    /// (a face a few units from a wall, behind a mounted board) that no link reaches from
    /// their side, so their rows sum far below their measured closure, which the closure
    /// fit cannot mend by scaling. Light from the direct columns still adds. Then the row
    /// guard is measured again.
    pub fn set_ray_rows(&mut self, rows: Vec<(u32, Vec<(u32, f32)>)>) {
        if rows.is_empty() {
            return;
        }
        let n = self.len();
        let full_count = rows.len() as u64;
        let mut full = vec![Vec::new(); n];
        let mut traced = vec![false; n];
        for (i, r) in rows {
            traced[i as usize] = true;
            full[i as usize] = r;
        }
        // The groups were fitted with these elements in them: their short rows raised the
        // scale of every other element of the group, which then gathered more than its
        // own closure (the conference's escaped light read −0.68 %, now −0.47 %). Fit
        // again without them.
        if let Some(c) = self.closure.take() {
            self.link_scale = vec![1.0; n];
            self.fit_closure(&c, &traced);
            self.closure = Some(c);
        }
        for (s, _) in self.link_scale.iter_mut().zip(&traced).filter(|(_, &t)| t) {
            *s = 0.0;
        }
        let rr = SparseRows::from_rows(full);
        self.stats.ray_rows = full_count;
        self.stats.ray_row_entries = rr.nnz() as u64;
        self.ray_rows = Some(rr);
        self.scale = vec![1.0; n];
        self.fixed_scale = vec![1.0; n];
        self.guard_rows();
    }

    /// Measures every row sum and scales rows above one to one (the row guard): what the
    /// links bring first, the direct columns and traced rows only where they alone sum
    /// above one. Those are per-element factors with shadow rays; the links are what
    /// overcounts (near contact, and where a cluster receiver hands a face light from
    /// directions its neighbours hide), and scaling the whole row took the lamp's exact
    /// light from the housing around it along with the links' excess (a two-sided
    /// classroom lamp housing: its row summed to 1.34, and 25 % of the tube's light on it
    /// went missing).
    fn guard_rows(&mut self) {
        let h = self;
        // Row sums: the product with x = 1 (every node's mean is 1).
        let sums = h.row_sums();
        let mut scaled = 0;
        let mut lifted = 0;
        let mut max_sum = 0.0f64;
        let mut worst = None;
        for (i, &s) in sums.iter().enumerate() {
            // The direct columns and traced row, which the closure fit does not scale
            // (needed only for rows above one).
            let fixed = if s > 1.0 { h.direct.as_ref().map_or(0.0, |d| d.row_sum(i)) + h.ray_rows.as_ref().map_or(0.0, |r| r.row_sum(i)) } else { 0.0 };
            if s > 1.0 {
                let links = s - fixed;
                if fixed < 1.0 && links > 0.0 {
                    h.scale[i] = ((1.0 - fixed) / links) as f32;
                } else {
                    h.scale[i] = 0.0;
                    h.fixed_scale[i] = (1.0 / fixed.max(1.0)) as f32;
                }
            }
            // Covered elements (no open area) gather but count for nothing.
            if h.tree.nodes[h.tree.leaf_of[i] as usize].area > 0.0 {
                if s > max_sum || worst.is_none() {
                    max_sum = s;
                    worst = Some(i as u64);
                }
                if s > 1.0 + 1e-3 {
                    scaled += 1;
                    // The row before the closure fit: its links unscaled, the direct
                    // columns and traced rows as they are.
                    let ls = f64::from(h.link_scale[i]);
                    let before = if ls > 0.0 { (s - fixed) / ls + fixed } else { s };
                    if before <= 1.0 + 1e-3 {
                        lifted += 1;
                    }
                }
            }
        }
        h.stats.rows_scaled = scaled;
        h.stats.rows_lifted = lifted;
        h.stats.max_row_sum = max_sum;
        h.stats.worst_row = worst;
        h.stats.memory_bytes = h.memory_bytes() as u64;
    }

    /// Fits what the links bring to the measured closure, group by group (see [`Closure`]),
    /// leaving out of the groups the elements marked in `traced` (their rows are traced).
    fn fit_closure(&mut self, c: &Closure, traced: &[bool]) {
        let n = self.len();
        let links = &self.link_ones;
        // Per group: area, Σ A·links, Σ A·direct, Σ A·closure, rays.
        let groups = c.group.iter().copied().max().map_or(0, |g| g as usize + 1);
        let is_traced = |i: usize| traced.get(i).copied().unwrap_or(false);
        let mut acc = vec![(0.0f64, 0.0f64, 0.0f64, 0.0f64, 0u64); groups];
        for i in 0..n {
            let a = self.tree.nodes[self.tree.leaf_of[i] as usize].area as f64;
            if !(a > 0.0 && c.fraction[i].is_finite()) || is_traced(i) {
                continue;
            }
            let d = self.direct.as_ref().map_or(0.0, |d| d.row_sum(i));
            let g = &mut acc[c.group[i] as usize];
            g.0 += a;
            g.1 += a * links[i];
            g.2 += a * d;
            g.3 += a * c.fraction[i] as f64;
            g.4 += c.rays as u64;
        }
        let scale: Vec<f64> = acc
            .iter()
            .map(|&(a, l, d, k, m)| {
                if !(a > 0.0 && l > 0.0 && m > 0) {
                    return 1.0;
                }
                let (l, d, p) = (l / a, d / a, k / a);
                let (lo, hi) = wilson(p, m as f64, CLOSURE_Z);
                let total = l + d;
                let target = if total < lo {
                    lo
                } else if total > hi {
                    hi
                } else {
                    return 1.0;
                };
                ((target - d).max(0.0) / l).clamp(CLOSURE_SCALE.0, CLOSURE_SCALE.1)
            })
            .collect();
        let (mut wsum, mut asum, mut fitted) = (0.0, 0.0, 0u64);
        for i in 0..n {
            let a = self.tree.nodes[self.tree.leaf_of[i] as usize].area as f64;
            // Every ray met a surface: either a closed neighbourhood (a crevice, the floor
            // under a desk) that its group's pooled rays would hide, or an element like the
            // rest of its group, whose m rays all hit with probability c_g^m (0.97¹⁶ =
            // 0.61). Fitted to the expected closure under the two (see CLOSED_PRIOR), not
            // to one: fitting all of them to one created light.
            let d = self.direct.as_ref().map_or(0.0, |d| d.row_sum(i));
            let s = if c.fraction[i] == 1.0 && a > 0.0 && links[i] > 0.0 {
                let gi = &acc[c.group[i] as usize];
                let pooled = if gi.0 > 0.0 { gi.3 / gi.0 } else { 1.0 };
                let typical = pooled.powf(c.rays as f64);
                let closed = CLOSED_PRIOR / (CLOSED_PRIOR + (1.0 - CLOSED_PRIOR) * typical);
                let t = pooled + (1.0 - pooled) * closed;
                ((t - d).max(0.0) / links[i]).clamp(CLOSURE_SCALE.0, CLOSURE_SCALE.1)
            } else {
                scale[c.group[i] as usize]
            };
            self.link_scale[i] = s as f32;
            if a > 0.0 && !is_traced(i) {
                wsum += a * s;
                asum += a;
                fitted += (s != 1.0) as u64;
            }
        }
        self.stats.closure_mean_scale = if asum > 0.0 { wsum / asum } else { 1.0 };
        self.stats.closure_fitted = fitted;
    }

    /// `y = F·x` without the row guard (its scaling and its cap at the largest `x`): what
    /// the links, the push and the direct columns deliver, for checks of conservation.
    pub fn gather_unguarded(&self, x: &[Rgb], y: &mut [Rgb]) {
        self.apply(x, y, false, true);
    }

    /// Every element's scale from the closure fit (1 where none was made).
    pub fn link_scale(&self) -> &[f32] {
        &self.link_scale
    }

    /// Every element's raw row sum `Σ_j F_ij` (before the guard's scaling).
    pub fn row_sums(&self) -> Vec<f64> {
        // The product with x = 1, from the links' own (see `link_ones`).
        (0..self.len())
            .map(|e| {
                self.link_ones[e] * self.link_scale[e] as f64
                    + self.direct.as_ref().map_or(0.0, |d| d.row_sum(e))
                    + self.ray_rows.as_ref().map_or(0.0, |r| r.row_sum(e))
            })
            .collect()
    }

    /// Pull – gather – push (see the module docs); `direct` adds the direct columns and
    /// `guard` applies the row scaling.
    fn apply(&self, x: &[Rgb], y: &mut [Rgb], guard: bool, direct: bool) {
        let nodes = &self.tree.nodes;
        let m = nodes.len();
        let mut buf = self.buffers.0.lock().ok().and_then(|mut b| b.take()).unwrap_or_default();
        let Buffers { near, far, mean, nb, nbx, sx, hi, g } = &mut buf;
        // Pull: area-weighted means and N_B = Σ A B n (per channel), bottom-up (every
        // entry is written below, so the kept buffers need no clearing).
        mean.resize(m, Rgb::ZERO);
        nb.resize(m, [DVec3::ZERO; 3]);
        nbx.resize(m, [DVec3::ZERO; 3]);
        sx.resize(m, Rgb::ZERO);
        // And the largest value below each node, which bounds a directional reading.
        hi.resize(m, Rgb::ZERO);
        for k in (0..m).rev() {
            let nd = &nodes[k];
            mean[k] = if nd.is_leaf() {
                let v = x[self.tree.order[nd.first as usize] as usize];
                let n = nd.n_sum.as_dvec3();
                nb[k] = [n * v.x, n * v.y, n * v.z];
                let n = nd.n_x.as_dvec3();
                nbx[k] = [n * v.x, n * v.y, n * v.z];
                sx[k] = v * nd.area_x as f64;
                hi[k] = v;
                v
            } else {
                let (c0, c1) = (nd.child[0] as usize, nd.child[1] as usize);
                nb[k] = [nb[c0][0] + nb[c1][0], nb[c0][1] + nb[c1][1], nb[c0][2] + nb[c1][2]];
                nbx[k] = [nbx[c0][0] + nbx[c1][0], nbx[c0][1] + nbx[c1][1], nbx[c0][2] + nbx[c1][2]];
                sx[k] = sx[c0] + sx[c1];
                hi[k] = hi[c0].max(hi[c1]);
                let (a, b) = (&nodes[nd.child[0] as usize], &nodes[nd.child[1] as usize]);
                let area = a.area as f64 + b.area as f64;
                if area > 0.0 {
                    (mean[nd.child[0] as usize] * a.area as f64 + mean[nd.child[1] as usize] * b.area as f64) / area
                } else {
                    Rgb::ZERO
                }
            };
        }
        // Gather per receiver node: irradiance at its centroid and its gradient (one
        // spatial vector per colour channel).
        // A cluster receiver holds its irradiance as a function of the normal instead,
        // `s + L·n + nᵀQn` per channel (s in the scalar, L in the gradient slots, Q here).
        g.clear();
        g.resize(m, (Rgb::ZERO, [DVec3::ZERO; 3]));
        // The sources' readings (see [`Reading`]).
        let slots = self.slot_node.len();
        near.resize(slots, Reading::default());
        far.resize(slots, Reading::default());
        near.par_iter_mut().zip(far.par_iter_mut()).zip(&self.slot_node).with_min_len(1024).for_each(|((rn, rf), &k)| {
            let k = k as usize;
            *rn = Reading { mean: mean[k], n: nb[k], hi: hi[k] };
            let ax = nodes[k].area_x as f64;
            *rf = if ax > 0.0 { Reading { mean: sx[k] / ax, n: nbx[k], hi: hi[k] } } else { *rn };
        });
        let src = Sources { near, far };
        g.par_iter_mut().enumerate().with_min_len(256).for_each(|(k, gk)| {
            if !nodes[k].surface {
                return; // cluster receivers below
            }
            let (a, b) = (self.link_start[k] as usize, self.link_start[k + 1] as usize);
            let mut acc = Rgb::ZERO;
            let mut grad = [DVec3::ZERO; 3];
            for t in a..b {
                if t + PREFETCH_AHEAD < b {
                    self.prefetch_source(k, t + PREFETCH_AHEAD, &src);
                }
                let src = self.source_value(k, t, &src);
                acc += src * self.factor(t);
                let gl = self.vec_of(k, t);
                if gl != [0.0; 3] {
                    let gv = Vec3::from_array(gl).as_dvec3();
                    for (c, gc) in grad.iter_mut().enumerate() {
                        *gc += gv * src[c];
                    }
                }
            }
            *gk = (acc, grad);
        });
        // Cluster receivers: irradiance by direction of arrival, walked down the clusters
        // (each path's bins summed on the way) and evaluated at the normal of each surface
        // child (see [`DIR_BIN_SIDE`]).
        if m > 0 && !nodes[0].surface {
            let mut bins = vec![[DVec3::ZERO; 3]; 2 * DIR_BINS];
            let mut lit = Vec::new();
            self.walk_clusters(0, &mut bins, &mut [0; 3], &src, &mut lit);
            let ex = &self.exclusions;
            let exs = &self.ex_slot;
            for (c, v) in lit {
                // Less what the walk handed the face from sources it cannot see (exclusions
                // sorted by face), clamped on the walk's own value: the face's other links
                // stay whole.
                let first = ex.partition_point(|e| e.c < c);
                let taken = ex[first..].iter().zip(&exs[first..]).take_while(|(e, _)| e.c == c).fold(Rgb::ZERO, |t, (e, &sl)| {
                    t + self.read_source(sl as usize, e.dir, e.near, &src) * e.coef as f64
                });
                g[c as usize].0 += (v - taken).max(Rgb::ZERO);
            }
        }
        // Push: every ancestor's irradiance, evaluated at the child's centroid, top-down
        // (clusters have handed theirs to their surface children above).
        for k in 0..m {
            let nd = &nodes[k];
            if !nd.surface {
                continue;
            }
            let (v, grad) = g[k];
            if nd.child[0] != NONE {
                for c in nd.child {
                    let d = (nodes[c as usize].centroid - nd.centroid).as_dvec3();
                    let gc = &mut g[c as usize];
                    gc.0 += v + Rgb::new(grad[0].dot(d), grad[1].dot(d), grad[2].dot(d));
                    for t in 0..3 {
                        gc.1[t] += grad[t];
                    }
                }
            } else {
                let e = self.tree.order[nd.first as usize] as usize;
                y[e] = v.max(Rgb::ZERO);
            }
        }
        // The closure's scale, emitted light through the direct columns, then the row guard:
        // rows summing to at most one, and no value above the largest of `x` (gradients
        // and normal-dependent pushes extrapolate, so rows that sum to one can still
        // amplify a non-uniform `x` slightly; with the cap ‖F·x‖∞ ≤ ‖x‖∞ holds and
        // Jacobi stays below E/(1 − ρ)).
        let top = buf.hi.first().copied().unwrap_or(Rgb::ZERO);
        y.par_iter_mut().enumerate().with_min_len(256).for_each(|(e, ye)| {
            *ye *= self.link_scale[e] as f64 * if guard { self.scale[e] as f64 } else { 1.0 };
            let mut fixed = Rgb::ZERO;
            if let Some(d) = self.direct.as_ref().filter(|_| direct) {
                fixed += d.gather_row(e, x);
            }
            if let Some(r) = &self.ray_rows {
                fixed += r.gather_row(e, x);
            }
            if guard {
                *ye = (*ye + fixed * self.fixed_scale[e] as f64).min(top);
            } else {
                *ye += fixed;
            }
        });
        if let Ok(mut kept) = self.buffers.0.lock() {
            *kept = Some(buf);
        }
    }

    /// Cluster receivers below node `k` (a cluster): adds `k`'s links to the directional
    /// `bins`, hands the sum to each surface child as `Σ_b max(0, n·V_b)` at its normal
    /// (appended to `out`) and recurses into cluster children; the bins are restored before
    /// returning. Large subtrees run in parallel on copies.
    ///
    /// `used` marks the bins that links on the path have touched (bit `b % 64` of word
    /// `b / 64`): the others hold exactly zero, so a surface child sums only the marked
    /// ones (in bin order, the same sums as over all 2 × [`DIR_BINS`]).
    fn walk_clusters(&self, k: usize, bins: &mut [[DVec3; 3]], used: &mut [u64; 3], src: &Sources, out: &mut Vec<(u32, Rgb)>) {
        const _: () = assert!(2 * DIR_BINS <= 3 * 64, "the bin marks are three words");
        let nodes = &self.tree.nodes;
        let (a, b) = (self.link_start[k] as usize, self.link_start[k + 1] as usize);
        // The bins this node's links change, with their old values (restored exactly), and
        // the marks it sets (cleared on return).
        let mut saved: Vec<(usize, [DVec3; 3])> = Vec::new();
        let mut marked = [0u64; 3];
        // Bins saved at this node: each once, before its first change here (a cluster's
        // links are many and their bins few; saving per link wrote 80 bytes a link).
        let mut kept = [0u64; 3];
        for t in a..b {
            if t + PREFETCH_AHEAD < b {
                self.prefetch_source(k, t + PREFETCH_AHEAD, src);
            }
            let w = self.source_value(k, t, src) * self.factor(t);
            let d = Vec3::from_array(self.vec_of(k, t)).as_dvec3();
            // Near links in the second half: they reach every face, far ones the exposed.
            let bin = dir_bin(d) + DIR_BINS * self.is_near(t) as usize;
            let (word, bit) = (bin / 64, 1u64 << (bin % 64));
            if kept[word] & bit == 0 {
                kept[word] |= bit;
                saved.push((bin, bins[bin]));
            }
            for c in 0..3 {
                bins[bin][c] += d * w[c];
            }
            if used[word] & bit == 0 {
                used[word] |= bit;
                marked[word] |= bit;
            }
        }
        let nd = &nodes[k];
        let is_cluster = |c: u32| c != NONE && !nodes[c as usize].surface;
        for c in nd.child {
            // No marks: no link on the path, nothing to hand out.
            if c == NONE || !nodes[c as usize].surface || *used == [0; 3] {
                continue;
            }
            let n = nodes[c as usize].normal();
            // Far bins (the first DIR_BINS) and near bins, each summed in bin order.
            let (mut far, mut near) = (Rgb::ZERO, Rgb::ZERO);
            for (word, &bits) in used.iter().enumerate() {
                let mut bits = bits;
                while bits != 0 {
                    let b = word * 64 + bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let bin = &bins[b];
                    let v = Rgb::new(n.dot(bin[0]).max(0.0), n.dot(bin[1]).max(0.0), n.dot(bin[2]).max(0.0));
                    if b < DIR_BINS {
                        far += v;
                    } else {
                        near += v;
                    }
                }
            }
            // Only its exposed part takes light that reaches the cluster from afar.
            out.push((c, far * self.tree.exposure(c) + near));
        }
        let [c0, c1] = nd.child;
        if is_cluster(c0) && is_cluster(c1) && nd.count as usize >= PARALLEL_WALK {
            let mut copy = bins.to_vec();
            let mut copy_used = *used;
            let mut other = Vec::new();
            rayon::join(
                || self.walk_clusters(c0 as usize, &mut copy, &mut copy_used, src, &mut other),
                || self.walk_clusters(c1 as usize, bins, used, src, out),
            );
            out.append(&mut other);
        } else {
            for c in nd.child.into_iter().filter(|&c| is_cluster(c)) {
                self.walk_clusters(c as usize, bins, used, src, out);
            }
        }
        for (bin, old) in saved.into_iter().rev() {
            bins[bin] = old;
        }
        for (u, m) in used.iter_mut().zip(marked) {
            *u &= !m;
        }
    }

    /// Starts loading what link `t` of receiver `k` will read of its source (see
    /// [`Hierarchy::source_value`]): its sources are nodes anywhere in the tree, one cache
    /// miss each when read cold.
    #[inline(always)]
    fn prefetch_source(&self, k: usize, t: usize, src: &Sources) {
        use crate::accel::prefetch;
        let s = self.link_src[t] as usize;
        if t >= self.first_cluster_link(k) && !self.is_near(t) {
            // A far cluster source: read by direction over its exposed faces (surface
            // sources, `Link::MEAN`, read the mean).
            let r = &src.far[s];
            prefetch(r);
            prefetch(&r.hi);
        } else {
            let r = &src.near[s];
            prefetch(r);
            prefetch(&r.hi);
        }
    }

    /// The source node of link `t`.
    #[inline]
    fn source_node(&self, t: usize) -> u32 {
        self.slot_node[self.link_src[t] as usize]
    }

    /// The factor of link `t`.
    #[inline]
    fn factor(&self, t: usize) -> f64 {
        self.link_f[t].abs() as f64
    }

    /// True for a near-field link ([`Link::near`]).
    #[inline]
    fn is_near(&self, t: usize) -> bool {
        self.link_f[t].is_sign_negative()
    }

    /// The vector of link `t` of receiver `k` (zero for a leaf receiver).
    #[inline]
    fn vec_of(&self, k: usize, t: usize) -> [f32; 3] {
        match self.g_base[k] {
            NONE => [0.0; 3],
            b => self.link_g[b as usize + t - self.link_start[k] as usize],
        }
    }

    /// The first of receiver `k`'s links whose source is a cluster (they come last in its
    /// list, see [`Hierarchy::from_parts`]).
    #[inline]
    fn first_cluster_link(&self, k: usize) -> usize {
        (self.link_start[k + 1] - self.cluster_count[k]) as usize
    }

    /// How link `t` of receiver `k` reads its source ([`Link::MEAN`] for a surface source).
    #[inline]
    fn read_of(&self, k: usize, t: usize) -> [f32; 4] {
        let first = self.first_cluster_link(k);
        if t < first {
            Link::MEAN
        } else {
            self.link_dir[self.dir_base[k] as usize + t - first]
        }
    }

    /// The radiosity link `t` reads from its source: the area-weighted mean, or for a
    /// cluster its directional reading ([`Link::directional`]).
    #[inline]
    fn source_value(&self, k: usize, t: usize, src: &Sources) -> Rgb {
        self.read_source(self.link_src[t] as usize, self.read_of(k, t), self.is_near(t), src)
    }

    /// The source in slot `s` read as `dir` says ([`Link::MEAN`] or
    /// [`Link::directional`]), over all its faces (`near`) or its exposed ones.
    #[inline]
    fn read_source(&self, s: usize, dir: [f32; 4], near: bool, src: &Sources) -> Rgb {
        if dir == Link::MEAN {
            src.near[s].mean
        } else {
            let r = if near { &src.near[s] } else { &src.far[s] };
            let (mean, n, hi) = (r.mean, &r.n, r.hi);
            let beta = Vec3::new(dir[1], dir[2], dir[3]).as_dvec3();
            // A weighted mean of the source's radiosities in truth; the first-order reading
            // can overshoot (normals that cancel, as on two-sided pairs) and is held to
            // the range they span, so that no link amplifies.
            (mean * dir[0] as f64 + Rgb::new(beta.dot(n[0]), beta.dot(n[1]), beta.dot(n[2])))
                .max(Rgb::ZERO)
                .min(hi)
        }
    }

    /// Source `s` read as `dir` says for radiosity `x`, from its leaves directly (no pull):
    /// what [`Hierarchy::read_source`] gives after the pull.
    fn leaf_reading(&self, x: &[Rgb], s: usize, dir: [f32; 4], near: bool) -> Rgb {
        let nodes = &self.tree.nodes;
        let s = &nodes[s];
        let (mut sum, mut sum_x, mut nb, mut nbx, mut hi) = (Rgb::ZERO, Rgb::ZERO, [DVec3::ZERO; 3], [DVec3::ZERO; 3], Rgb::ZERO);
        for slot in s.first..s.first + s.count {
            let e = self.tree.order[slot as usize] as usize;
            let leaf = &nodes[self.tree.leaf_of[e] as usize];
            let v = x[e];
            hi = hi.max(v);
            sum += v * leaf.area as f64;
            sum_x += v * leaf.area_x as f64;
            let n = leaf.n_sum.as_dvec3();
            nb = [nb[0] + n * v.x, nb[1] + n * v.y, nb[2] + n * v.z];
            let n = leaf.n_x.as_dvec3();
            nbx = [nbx[0] + n * v.x, nbx[1] + n * v.y, nbx[2] + n * v.z];
        }
        let mean = if s.area > 0.0 { sum / s.area as f64 } else { Rgb::ZERO };
        if dir == Link::MEAN {
            return mean;
        }
        let beta = Vec3::new(dir[1], dir[2], dir[3]).as_dvec3();
        let (mean, nb) = if near || !(s.area_x > 0.0) { (mean, nb) } else { (sum_x / s.area_x as f64, nbx) };
        (mean * dir[0] as f64 + Rgb::new(beta.dot(nb[0]), beta.dot(nb[1]), beta.dot(nb[2]))).max(Rgb::ZERO).min(hi)
    }

    /// The faces that cluster receivers' links must not light ([`Exclusion`]).
    pub fn exclusions(&self) -> &[Exclusion] {
        &self.exclusions
    }

    /// The power the links carry for radiosity `x`, `Σ_links A_R · f · B̃_S` (luminance of
    /// RGB; for a cluster receiver each leaf's share by its normal, see [`DIR_BIN_SIDE`]),
    /// summed link by link without the push: what the leaves must receive in all (the
    /// push–pull conservation check; equal to `Σ_i A_i (F·x)_i` while no row is scaled and
    /// no leaf's normal-dependent irradiance, nor a face's irradiance less its exclusions, is clamped at zero).
    pub fn link_power(&self, x: &[Rgb]) -> f64 {
        let nodes = &self.tree.nodes;
        let mut total = 0.0;
        for k in 0..nodes.len() {
            let (a, b) = (self.link_start[k] as usize, self.link_start[k + 1] as usize);
            for t in a..b {
                let src = self.leaf_reading(x, self.source_node(t) as usize, self.read_of(k, t), self.is_near(t));
                let w = self.factor(t) * crate::luminance(src);
                if nodes[k].surface {
                    total += nodes[k].area as f64 * w;
                } else {
                    // A cluster receiver: each leaf by its normal.
                    let d = Vec3::from_array(self.vec_of(k, t)).as_dvec3();
                    total += w * self.tree.front_area(k as u32, d, !self.is_near(t));
                }
            }
        }
        for ex in &self.exclusions {
            let src = self.leaf_reading(x, ex.s as usize, ex.dir, ex.near);
            total -= ex.coef as f64 * crate::luminance(src) * nodes[ex.c as usize].area as f64;
        }
        total
    }

    /// The power the direct columns carry for radiosity `x` (luminance; zero without
    /// them): `Σ_i A_i Σ_j D_ij x_j`, with `A_i` the open area of element `i`.
    pub fn direct_power(&self, x: &[Rgb]) -> f64 {
        let Some(d) = &self.direct else { return 0.0 };
        let nodes = &self.tree.nodes;
        (0..self.len())
            .map(|e| nodes[self.tree.leaf_of[e] as usize].area as f64 * crate::luminance(d.gather_row(e, x)))
            .sum()
    }

    /// The exact factors to the emitting elements, when emitted light travels outside the
    /// links.
    pub fn direct(&self) -> Option<&SparseRows> {
        self.direct.as_ref()
    }

    /// The closure the links were fitted to, if any ([`Hierarchy::from_parts`]).
    pub fn closure(&self) -> Option<&Closure> {
        self.closure.as_ref()
    }

    /// The rows traced by rays in place of links ([`Hierarchy::set_ray_rows`]), if any.
    pub fn ray_rows(&self) -> Option<&SparseRows> {
        self.ray_rows.as_ref()
    }

    /// Links received by node `k` with their vectors and readings: (source node, factor,
    /// gradient or direction of arrival, reading), for diagnostics.
    pub fn links_full(&self, k: u32) -> impl Iterator<Item = (u32, f32, [f32; 3], [f32; 4])> + '_ {
        let k = k as usize;
        (self.link_start[k] as usize..self.link_start[k + 1] as usize)
            .map(move |t| (self.source_node(t), self.link_f[t].abs(), self.vec_of(k, t), self.read_of(k, t)))
    }

    /// Links received by node `k`: (source node, factor).
    pub fn links(&self, k: u32) -> impl Iterator<Item = (u32, f32)> + '_ {
        let (a, b) = (self.link_start[k as usize] as usize, self.link_start[k as usize + 1] as usize);
        self.link_src[a..b].iter().map(|&sl| self.slot_node[sl as usize]).zip(self.link_f[a..b].iter().map(|f| f.abs()))
    }
}

impl Transport for Hierarchy {
    fn len(&self) -> usize {
        self.tree.order.len()
    }

    fn gather(&self, x: &[Rgb], y: &mut [Rgb]) {
        self.apply(x, y, true, true);
    }

    fn release_buffers(&self) {
        if let Ok(mut kept) = self.buffers.0.lock() {
            *kept = None;
        }
    }

    fn memory_bytes(&self) -> usize {
        let t = &self.tree;
        t.nodes.len() * std::mem::size_of::<Node>()
            + (t.order.len() + t.leaf_of.len()) * 4
            + (t.area_prefix.len() + t.exposed_prefix.len()) * 8
            + t.normal_start.len() * 4
            + (t.normal_bins.len() + t.normal_bins_exposed.len() + t.top_n.len() + t.top_nx.len()) * 12
            + t.top_range.len() * 8
            + t.top_id.len() * 4
            + self.link_start.len() * 4
            + (self.link_src.len() + self.slot_node.len() + self.ex_slot.len()) * 4
            + self.link_ones.len() * 8
            + self.link_f.len() * 4
            + self.link_g.len() * 12
            + self.link_dir.len() * 16
            + (self.g_base.len() + self.dir_base.len() + self.cluster_count.len()) * 4
            + (self.scale.len() + self.fixed_scale.len() + self.link_scale.len()) * 4
            + self.exclusions.len() * std::mem::size_of::<Exclusion>()
            + self.closure.as_ref().map_or(0, |c| (c.fraction.len() + c.group.len()) * 4)
            + self.direct.as_ref().map_or(0, |d| d.nnz() * 8 + (d.n() + 1) * 8)
            + self.ray_rows.as_ref().map_or(0, |d| d.nnz() * 8 + (d.n() + 1) * 8)
    }
}
