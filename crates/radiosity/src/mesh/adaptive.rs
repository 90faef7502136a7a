//! Adaptive meshing: the uniform element mesh refined where radiosity changes fast.
//!
//! Every uniform element is the root of a tree; a refined quadrilateral splits into four at
//! its bilinear edge midpoints and centre, a refined triangle into four at its edge
//! midpoints (substructuring, Cohen, Greenberg, Immel & Brock 1986, "An efficient radiosity
//! approach for realistic image synthesis"). An element is refined while its error estimate
//! exceeds [`Options::threshold`], up to [`Options::max_depth`] levels and
//! [`Options::max_elements`] elements in all (a hard limit: the most important splits are
//! kept, see [`Refiner::refine_leaves`]).
//!
//! **Error estimates** (each per element, in units of the scene's mean exitance, so that a
//! threshold of 0.1 means "a tenth of the average brightness"):
//! - *a priori, direct light* ([`a_priori_errors`]): the reflected direct exitance `ρ·H_d`
//!   (exact point-to-polygon factor times ray-sampled visibility of every emitter,
//!   [`crate::direct::direct_irradiance`], the same stratified shadow rays at every
//!   point so that differences show light, not noise) near the corners, near the edge
//!   midpoints and at the centroid; the error is the largest difference between a midpoint
//!   or centre value and the (bi)linear interpolation of the corner values there — what
//!   Gouraud interpolation of the element gets wrong. It finds shadow boundaries and the
//!   cut-off of direct light at contact lines before anything is solved, and leaves alone
//!   light that is bright but varies linearly (the spread of the values instead spent a fifth
//!   of the elements on the top of the tall Cornell block, nearest the light).
//! - *a priori, contact*: elements that a contact line crosses (open fraction strictly
//!   between 0 and 1, [`super::coverage`]) get an infinite error: refined first, to full
//!   depth, so that little area is averaged across the contact.
//! - *a posteriori, indirect light* ([`a_posteriori_errors`]): after a solve, the reflected
//!   indirect exitance `ρ·F·(B − E)` — what final gathering interpolates — is reconstructed
//!   per vertex ([`crate::reconstruct`]) and the error of an element is the largest
//!   difference between its own value and its vertices'. It finds contact edges and room
//!   corners, where indirect light changes fastest. Form factors and coverage are then
//!   recomputed for the whole new mesh (reusing the rows of unchanged elements is not done:
//!   the point-sampled rows are renormalised per source patch, so a split source changes
//!   every row that sees it).
//!
//! Refinement goes one level per round; when [`Options::max_elements`] cuts a round short,
//! the splits with the largest `error × √area` (share of the squared error over the
//! surfaces) are kept. (Spending only half the remaining elements per round, to go deep
//! where the error is largest first, measured no better: Gouraud 2.76 % against 2.74 % at
//! the default settings, 3.68 % against 3.55 % from a coarser start.)
//!
//! What it buys (Cornell box, BENCHMARKS.md "Adaptive meshing"): at the same element count
//! the Gouraud image is a little closer to the path tracer than a finer uniform mesh (the
//! shadows on the floor are resolved) while the final-gather image is a little further
//! (it computes direct light per pixel, so elements spent on shadows are wasted on it, and
//! the indirect light of this scene is smooth enough for a uniform mesh); hence uniform
//! meshing stays the default and `--adaptive` is for Gouraud output and scenes whose
//! shadows are sharper.
//!
//! These approximate discontinuity meshing (Lischinski, Tampieri & Greenberg 1992), which
//! places element edges exactly along shadow and contact lines; here the mesh only gets
//! finer near them.
//!
//! **Conformity** (Baum, Mann, Smith & Winget 1991, "Making radiosity usable: automatic
//! preprocessing and meshing techniques for the generation of accurate radiosity
//! solutions"): the trees are kept *balanced* — an element edge is never split twice while
//! the element on its other side is whole (2:1 rule) — and an element with a split
//! neighbour (a *hanging* midpoint on its edge) is emitted as a transition: a fan of
//! triangles from the hanging midpoint, adjacent pairs merged back into convex quads where
//! possible (one hanging midpoint: a trapezoid and a triangle; two opposite ones: two
//! quads). An element all of whose edges hang is split instead. So no vertex lies inside
//! another element's edge within a patch, and Gouraud interpolation has no T-vertex seams.
//!
//! **Across patches**: edges are identified by welded vertices (position, material and
//! plane, as [`crate::reconstruct::Welding`] welds them), so where uniform meshing gave two
//! coplanar patches of the same material matching vertices along their common edge, a
//! split on one side makes the other side a transition element too (and balance propagates
//! across): the welded mesh stays conforming. Coplanar patches whose uniform grids did not
//! match along the common edge (e.g. the Cornell ceiling's four quads around the light)
//! were not conforming before refinement and are not made so; creases and material edges
//! are never welded and need nothing.
//!
//! Refinement keeps [`Mesh`]'s invariants: elements of a patch contiguous, vertices shared
//! within a patch, planar convex counter-clockwise triangles and quads, areas summing to the
//! patch's area.

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use super::{Element, Mesh, PatchElements, Receivers, NO_VERTEX};
use crate::accel::SceneRays;
use crate::direct::{direct_irradiance, emitters};
use crate::sampling::{rng_for, stratified};
use crate::scene::{newell_normal, polygon_centroid, Scene};
use crate::{luminance, Progress, Rgb};

/// How to refine.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Refine an element whose error estimate (in units of the scene's mean exitance, see
    /// the module docs) exceeds this.
    pub threshold: f64,
    /// Most 1 → 4 splits below a uniform element.
    pub max_depth: u32,
    /// Most elements after refinement, transition elements included (None: twice the
    /// uniform mesh's count).
    pub max_elements: Option<usize>,
    /// A priori: refine where direct light is not (bi)linear across an element.
    pub direct: bool,
    /// A priori: refine elements that a contact line crosses.
    pub contact: bool,
    /// A posteriori passes (solve, refine on the indirect light, solve again); 0 = none.
    pub passes: usize,
    /// Shadow rays per estimate point and emitter for the direct-light estimate, `n × n`.
    pub shadow_samples: usize,
}

impl Default for Options {
    /// The settings measured best for Gouraud images of the Cornell box at a given element
    /// count (BENCHMARKS.md, "Adaptive meshing"): one or two levels below the default
    /// uniform size where direct light bends, up to twice the uniform count.
    fn default() -> Self {
        Options { threshold: 0.1, max_depth: 2, max_elements: None, direct: true, contact: true, passes: 0, shadow_samples: 4 }
    }
}

impl Options {
    /// The element limit for a uniform mesh of `base` elements.
    pub fn limit(&self, base: usize) -> usize {
        self.max_elements.unwrap_or(2 * base)
    }
}

/// What one refinement did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PassStats {
    /// Elements before.
    pub elements_before: usize,
    /// Elements after (transition elements included).
    pub elements_after: usize,
    /// Elements whose error exceeded the threshold.
    pub over_threshold: usize,
    /// Tree nodes split (including splits forced by balance).
    pub splits: usize,
    /// Whether [`Options::max_elements`] cut refinement short.
    pub capped: bool,
}

const LEAF: u32 = u32::MAX;

#[derive(Clone, Copy, Debug)]
struct Node {
    /// Vertex ids (per patch, as in [`Mesh`]), CCW; `corners[3] == NO_VERTEX` for triangles.
    corners: [u32; 4],
    patch: u32,
    level: u8,
    /// First of four consecutive children, or [`LEAF`].
    children: u32,
}

impl Node {
    fn n(&self) -> usize {
        if self.corners[3] == NO_VERTEX {
            3
        } else {
            4
        }
    }
}

type WeldKey = ([i64; 3], u32, [i32; 3]);

/// The refinement trees of every patch, and the conforming mesh they give.
#[derive(Clone, Debug)]
pub struct Refiner {
    positions: Vec<DVec3>,
    /// Welded identity of every vertex (position, material, plane).
    weld_of: Vec<u32>,
    welds: HashMap<WeldKey, u32>,
    /// Per patch, vertex by rounded position.
    patch_vertex: HashMap<(u32, [u64; 3]), u32>,
    /// Split edges (welded end points, sorted) and the welded midpoint.
    split: HashMap<(u32, u32), u32>,
    nodes: Vec<Node>,
    roots: Vec<Vec<u32>>,
    patch_normal: Vec<DVec3>,
    patch_material: Vec<u32>,
    quantum: f64,
    target_size: f64,
    mesh: Mesh,
    /// Tree leaf of every element of `mesh`.
    leaf_of: Vec<u32>,
    /// Elements of the uniform mesh.
    base: usize,
}

impl Refiner {
    /// Trees whose roots are the elements of `mesh` (a uniform mesh of `scene`).
    pub fn new(scene: &Scene, mesh: &Mesh) -> Refiner {
        let mut r = Refiner {
            positions: Vec::with_capacity(mesh.positions.len()),
            weld_of: Vec::new(),
            welds: HashMap::new(),
            patch_vertex: HashMap::new(),
            split: HashMap::new(),
            nodes: Vec::with_capacity(mesh.len()),
            roots: vec![Vec::new(); scene.polygons.len()],
            patch_normal: scene.polygons.iter().map(|p| p.normal).collect(),
            patch_material: scene.polygons.iter().map(|p| p.material).collect(),
            quantum: (scene.diagonal() * 1e-7).max(f64::MIN_POSITIVE),
            target_size: mesh.target_size,
            mesh: Mesh::default(),
            leaf_of: Vec::new(),
            base: mesh.len(),
        };
        let mut remap = vec![u32::MAX; mesh.positions.len()];
        for e in &mesh.elements {
            let mut corners = [NO_VERTEX; 4];
            for (c, &v) in corners.iter_mut().zip(&e.vertices[..e.vertex_count()]) {
                let v = v as usize;
                if remap[v] == u32::MAX {
                    remap[v] = r.vertex(e.patch, mesh.positions[v]);
                }
                *c = remap[v];
            }
            r.roots[e.patch as usize].push(r.nodes.len() as u32);
            r.nodes.push(Node { corners, patch: e.patch, level: 0, children: LEAF });
        }
        let (m, leaf_of) = r.emit();
        r.mesh = m;
        r.leaf_of = leaf_of;
        r
    }

    /// The current (conforming) mesh.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Refinement depth of every element of [`Refiner::mesh`] (0 = a uniform element).
    pub fn depths(&self) -> Vec<u32> {
        self.leaf_of.iter().map(|&l| self.nodes[l as usize].level as u32).collect()
    }

    /// One element per tree leaf (the leaf itself, before transitions) and the leaf ids;
    /// errors estimated on these are stable while a leaf stays a leaf.
    pub fn leaf_mesh(&self) -> (Mesh, Vec<u32>) {
        let leaves = self.leaves();
        let mut elements = Vec::with_capacity(leaves.len());
        let mut ids = Vec::with_capacity(leaves.len());
        for &l in &leaves {
            let node = &self.nodes[l as usize];
            if self.push_element(&mut elements, &node.corners[..node.n()], node.patch, self.patch_normal[node.patch as usize]) {
                ids.push(l);
            }
        }
        let mut patches = vec![PatchElements::default(); self.roots.len()];
        for (i, e) in elements.iter().enumerate() {
            let pe = &mut patches[e.patch as usize];
            if pe.count == 0 {
                pe.first = i as u32;
            }
            pe.count += 1;
        }
        (Mesh { positions: self.positions.clone(), elements, patches, target_size: self.target_size }, ids)
    }

    /// Splits the leaves of the elements whose `errors` (one per element of
    /// [`Refiner::mesh`]) exceed the threshold; see [`Refiner::refine_leaves`].
    pub fn refine(&mut self, errors: &[f64], opts: &Options) -> PassStats {
        assert_eq!(errors.len(), self.mesh.len(), "one error per element");
        let pairs: Vec<(u32, f64)> = errors.iter().enumerate().map(|(e, &err)| (self.leaf_of[e], err)).collect();
        self.refine_leaves(&pairs, opts)
    }

    /// Splits once every leaf whose error (pairs of leaf id and error; a leaf's error is the
    /// largest given for it) exceeds `opts.threshold`, below `opts.max_depth`, then balances
    /// and rebuilds the mesh. When the result would exceed `opts.max_elements`, only the
    /// most important splits are kept — largest `error × √area` first, i.e. the largest
    /// share of the squared error over the surfaces — as many as fit (found by bisection).
    pub fn refine_leaves(&mut self, errors: &[(u32, f64)], opts: &Options) -> PassStats {
        self.refine_leaves_to(errors, opts, opts.limit(self.base))
    }

    fn refine_leaves_to(&mut self, errors: &[(u32, f64)], opts: &Options, limit: usize) -> PassStats {
        let before = self.mesh.len();
        let mut best: HashMap<u32, f64> = HashMap::new();
        for &(leaf, err) in errors {
            if err.is_nan() || err <= opts.threshold || self.nodes[leaf as usize].children != LEAF {
                continue;
            }
            let b = best.entry(leaf).or_insert(0.0);
            *b = b.max(err);
        }
        let over = best.len();
        best.retain(|&leaf, _| (self.nodes[leaf as usize].level as u32) < opts.max_depth);
        // Largest contribution to the squared image error first: error² × area.
        let mut cands: Vec<(u32, f64)> = best.into_iter().map(|(l, e)| (l, e * self.node_area(l).sqrt())).collect();
        cands.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let mut stats = PassStats { elements_before: before, elements_after: before, over_threshold: over, ..Default::default() };
        if cands.is_empty() {
            return stats;
        }
        let attempt = |k: usize| -> (Refiner, usize) {
            let mut t = self.clone();
            let mut splits = 0;
            for &(leaf, _) in &cands[..k] {
                if t.nodes[leaf as usize].children == LEAF {
                    t.split_node(leaf);
                    splits += 1;
                }
            }
            splits += t.balance();
            let (m, leaf_of) = t.emit();
            t.mesh = m;
            t.leaf_of = leaf_of;
            (t, splits)
        };
        let (mut t, mut splits) = attempt(cands.len());
        if t.mesh.len() > limit {
            stats.capped = true;
            // Largest k whose result fits; k = 0 is the current mesh.
            let (mut lo, mut hi) = (0usize, cands.len());
            let mut fit: Option<(Refiner, usize)> = None;
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                let (tm, s) = attempt(mid);
                if tm.mesh.len() <= limit {
                    lo = mid;
                    fit = Some((tm, s));
                } else {
                    hi = mid;
                }
            }
            match fit {
                Some((tm, s)) => {
                    t = tm;
                    splits = s;
                }
                None => return stats,
            }
        }
        *self = t;
        stats.splits = splits;
        stats.elements_after = self.mesh.len();
        stats
    }

    fn node_area(&self, id: u32) -> f64 {
        let node = &self.nodes[id as usize];
        let c: Vec<DVec3> = node.corners[..node.n()].iter().map(|&v| self.positions[v as usize]).collect();
        0.5 * newell_normal(&c).length()
    }

    fn weld(&mut self, patch: u32, p: DVec3) -> u32 {
        let q = self.quantum;
        let n = self.patch_normal[patch as usize];
        let s = 1e4;
        let key = (
            [(p.x / q).round() as i64, (p.y / q).round() as i64, (p.z / q).round() as i64],
            self.patch_material[patch as usize],
            [(n.x * s).round() as i32, (n.y * s).round() as i32, (n.z * s).round() as i32],
        );
        let next = self.welds.len() as u32;
        *self.welds.entry(key).or_insert(next)
    }

    fn vertex(&mut self, patch: u32, p: DVec3) -> u32 {
        let key = (patch, [super::uniform::round_key(p.x), super::uniform::round_key(p.y), super::uniform::round_key(p.z)]);
        if let Some(&v) = self.patch_vertex.get(&key) {
            return v;
        }
        let w = self.weld(patch, p);
        self.positions.push(p);
        self.weld_of.push(w);
        let v = (self.positions.len() - 1) as u32;
        self.patch_vertex.insert(key, v);
        v
    }

    fn edge_key(&self, a: u32, b: u32) -> (u32, u32) {
        let (wa, wb) = (self.weld_of[a as usize], self.weld_of[b as usize]);
        (wa.min(wb), wa.max(wb))
    }

    /// The welded midpoint of edge (a, b) if some element on either side split it.
    fn hanging(&self, a: u32, b: u32) -> Option<u32> {
        self.split.get(&self.edge_key(a, b)).copied()
    }

    fn split_node(&mut self, id: u32) {
        let node = self.nodes[id as usize];
        let n = node.n();
        let c = node.corners;
        let p = |v: u32, s: &Self| s.positions[v as usize];
        let mut mid = [NO_VERTEX; 4];
        for k in 0..n {
            let (a, b) = (c[k], c[(k + 1) % n]);
            let m = self.vertex(node.patch, 0.5 * (p(a, self) + p(b, self)));
            mid[k] = m;
            let key = self.edge_key(a, b);
            let wm = self.weld_of[m as usize];
            self.split.insert(key, wm);
        }
        let kids: [[u32; 4]; 4] = if n == 4 {
            let centre = 0.25 * (p(c[0], self) + p(c[1], self) + p(c[2], self) + p(c[3], self));
            let ctr = self.vertex(node.patch, centre);
            // Interior edges of the split are split edges of the children, not of this
            // node: nothing hangs on them until a child splits.
            [
                [c[0], mid[0], ctr, mid[3]],
                [mid[0], c[1], mid[1], ctr],
                [ctr, mid[1], c[2], mid[2]],
                [mid[3], ctr, mid[2], c[3]],
            ]
        } else {
            [
                [c[0], mid[0], mid[2], NO_VERTEX],
                [mid[0], c[1], mid[1], NO_VERTEX],
                [mid[2], mid[1], c[2], NO_VERTEX],
                [mid[1], mid[2], mid[0], NO_VERTEX],
            ]
        };
        let first = self.nodes.len() as u32;
        for corners in kids {
            self.nodes.push(Node { corners, patch: node.patch, level: node.level + 1, children: LEAF });
        }
        self.nodes[id as usize].children = first;
    }

    /// Whether leaf `id` must split: an edge of it is split twice (its neighbour there is
    /// two levels finer), or every edge of it hangs.
    fn unbalanced(&self, id: u32) -> bool {
        let node = &self.nodes[id as usize];
        let n = node.n();
        let mut hanging = 0;
        for k in 0..n {
            let (a, b) = (node.corners[k], node.corners[(k + 1) % n]);
            let Some(wm) = self.hanging(a, b) else { continue };
            hanging += 1;
            let (wa, wb) = (self.weld_of[a as usize], self.weld_of[b as usize]);
            let sub = |x: u32, y: u32| self.split.contains_key(&(x.min(y), x.max(y)));
            if sub(wa, wm) || sub(wm, wb) {
                return true;
            }
        }
        hanging == n
    }

    /// Splits leaves until the 2:1 rule holds everywhere; returns the splits made.
    fn balance(&mut self) -> usize {
        let mut total = 0;
        loop {
            let todo: Vec<u32> = self.leaves().into_iter().filter(|&l| self.unbalanced(l)).collect();
            if todo.is_empty() {
                return total;
            }
            for l in todo {
                if self.nodes[l as usize].children == LEAF {
                    self.split_node(l);
                    total += 1;
                }
            }
        }
    }

    /// Leaves, patch by patch, in tree order.
    fn leaves(&self) -> Vec<u32> {
        let mut out = Vec::with_capacity(self.nodes.len());
        let mut stack = Vec::new();
        for roots in &self.roots {
            for &r in roots {
                stack.push(r);
                while let Some(id) = stack.pop() {
                    let c = self.nodes[id as usize].children;
                    if c == LEAF {
                        out.push(id);
                    } else {
                        stack.extend([c + 3, c + 2, c + 1, c]);
                    }
                }
            }
        }
        out
    }

    /// The conforming mesh of the current leaves and the leaf of every element.
    fn emit(&mut self) -> (Mesh, Vec<u32>) {
        let leaves = self.leaves();
        let mut elements = Vec::with_capacity(leaves.len() + leaves.len() / 4);
        let mut leaf_of = Vec::with_capacity(elements.capacity());
        let mut patches = vec![PatchElements::default(); self.roots.len()];
        let mut poly: Vec<(u32, bool)> = Vec::with_capacity(8);
        let mut li = 0;
        for (pi, pe) in patches.iter_mut().enumerate() {
            pe.first = elements.len() as u32;
            while li < leaves.len() && self.nodes[leaves[li] as usize].patch == pi as u32 {
                let id = leaves[li];
                li += 1;
                let node = self.nodes[id as usize];
                let n = node.n();
                poly.clear();
                for k in 0..n {
                    let (a, b) = (node.corners[k], node.corners[(k + 1) % n]);
                    poly.push((a, false));
                    if self.hanging(a, b).is_some() {
                        let m = 0.5 * (self.positions[a as usize] + self.positions[b as usize]);
                        poly.push((self.vertex(node.patch, m), true));
                    }
                }
                let normal = self.patch_normal[pi];
                if poly.len() == n {
                    self.push_element(&mut elements, &node.corners[..n], node.patch, normal);
                    leaf_of.push(id);
                    continue;
                }
                // Transition: fan from the first hanging midpoint, merging neighbouring fan
                // triangles into strictly convex quads.
                let s = poly.iter().position(|v| v.1).unwrap();
                poly.rotate_left(s);
                let m = poly[0].0;
                let last = poly.len() - 1;
                let mut i = 1;
                while i < last {
                    if i + 2 <= last && self.strictly_convex(&[m, poly[i].0, poly[i + 1].0, poly[i + 2].0], normal) {
                        let q = [m, poly[i].0, poly[i + 1].0, poly[i + 2].0];
                        if self.push_element(&mut elements, &q, node.patch, normal) {
                            leaf_of.push(id);
                        }
                        i += 2;
                    } else {
                        let t = [m, poly[i].0, poly[i + 1].0];
                        if self.push_element(&mut elements, &t, node.patch, normal) {
                            leaf_of.push(id);
                        }
                        i += 1;
                    }
                }
            }
            pe.count = elements.len() as u32 - pe.first;
        }
        let mesh = Mesh { positions: self.positions.clone(), elements, patches, target_size: self.target_size };
        (mesh, leaf_of)
    }

    fn strictly_convex(&self, q: &[u32; 4], normal: DVec3) -> bool {
        let p: Vec<DVec3> = q.iter().map(|&v| self.positions[v as usize]).collect();
        (0..4).all(|k| {
            let (a, b, c) = (p[k], p[(k + 1) % 4], p[(k + 2) % 4]);
            let (u, w) = (b - a, c - b);
            u.cross(w).dot(normal) > 1e-3 * u.length() * w.length()
        })
    }

    fn push_element(&self, out: &mut Vec<Element>, vs: &[u32], patch: u32, normal: DVec3) -> bool {
        let corners: Vec<DVec3> = vs.iter().map(|&v| self.positions[v as usize]).collect();
        let area = 0.5 * newell_normal(&corners).length();
        if area.is_nan() || area <= 0.0 {
            return false;
        }
        let mut vertices = [NO_VERTEX; 4];
        vertices[..vs.len()].copy_from_slice(vs);
        out.push(Element { vertices, patch, area, centroid: polygon_centroid(&corners), normal });
        true
    }
}

/// Area-weighted mean of `value` over the non-emitting elements — emitters would set the
/// scale by their own brightness — or over all elements when everything emits (the
/// furnace); at least a tiny positive number.
fn mean_exitance(scene: &Scene, mesh: &Mesh, value: impl Fn(usize) -> f64) -> f64 {
    let mut acc = [(0.0, 0.0); 2];
    for (i, e) in mesh.elements.iter().enumerate() {
        let m = &scene.materials[scene.polygons[e.patch as usize].material as usize];
        let k = m.is_emitter() as usize;
        acc[k].0 += value(i) * e.area;
        acc[k].1 += e.area;
    }
    let (s, a) = if acc[0].1 > 0.0 { acc[0] } else { (acc[0].0 + acc[1].0, acc[0].1 + acc[1].1) };
    if a > 0.0 && s > 0.0 {
        s / a
    } else {
        f64::MIN_POSITIVE
    }
}

/// Reflected direct exitance `lum(ρ·H_d)` on one element: near its corners, near its edge
/// midpoints and at its centroid (units of the scene's exitance).
#[derive(Clone, Copy, Debug, Default)]
struct DirectSample {
    n: usize,
    corners: [f64; 4],
    mids: [f64; 4],
    centre: f64,
}

impl DirectSample {
    /// Largest difference between a midpoint or centre sample and the (bi)linear
    /// interpolation of the corner samples there: what Gouraud interpolation of this element
    /// would get wrong, zero for light that varies linearly.
    fn interpolation_error(&self) -> f64 {
        let n = self.n;
        if n == 0 {
            return 0.0;
        }
        let mean = self.corners[..n].iter().sum::<f64>() / n as f64;
        let mut e = (self.centre - mean).abs();
        for k in 0..n {
            e = e.max((self.mids[k] - 0.5 * (self.corners[k] + self.corners[(k + 1) % n])).abs());
        }
        e
    }
}

/// [`DirectSample`]s of every element and the rays cast.
fn direct_samples(scene: &Scene, mesh: &Mesh, rays: &SceneRays, opts: &Options) -> (Vec<DirectSample>, u64) {
    let ems = emitters(scene);
    let k = opts.shadow_samples.max(1);
    // One fixed stratified pattern per emitter, the same at every point: differences
    // between the points then show the light, not the sampling noise.
    let patterns: Vec<Vec<(f64, f64)>> = (0..ems.len())
        .map(|e| {
            let mut v = Vec::new();
            stratified(k, &mut rng_for(0xada9, e as u64), &mut v);
            v
        })
        .collect();
    let per: Vec<(DirectSample, u64)> = mesh
        .elements
        .par_iter()
        .with_min_len(16)
        .map(|e| {
            let mut out = DirectSample::default();
            let mat = &scene.materials[scene.polygons[e.patch as usize].material as usize];
            if mat.reflectance.max_element() <= 0.0 {
                return (out, 0);
            }
            let (c, n) = e.corners(&mesh.positions);
            out.n = n;
            let mut r = 0;
            let mut at = |x: DVec3| {
                // Points pulled slightly inside: on the boundary itself a point may lie in
                // the plane of a touching surface.
                let x = x.lerp(e.centroid, 0.02);
                let (h, rr) = direct_irradiance(scene, rays, &ems, x, e.normal, e.patch, |em| &patterns[em]);
                r += rr;
                luminance(mat.reflectance * h)
            };
            for k in 0..n {
                out.corners[k] = at(c[k]);
                out.mids[k] = at(0.5 * (c[k] + c[(k + 1) % n]));
            }
            out.centre = at(e.centroid);
            (out, r)
        })
        .collect();
    let nrays = per.iter().map(|p| p.1).sum();
    (per.into_iter().map(|p| p.0).collect(), nrays)
}

/// Error per element from direct-light samples (in units of `scale`) and receivers.
fn errors_from(samples: Option<&[DirectSample]>, receivers: Option<&Receivers>, n: usize, scale: f64) -> Vec<f64> {
    let mut err = vec![0.0; n];
    if let Some(samples) = samples {
        for (e, v) in err.iter_mut().zip(samples) {
            *e = v.interpolation_error() / scale;
        }
    }
    if let Some(rec) = receivers {
        for (e, f) in err.iter_mut().zip(&rec.open_fraction) {
            if *f > 0.0 && *f < 1.0 {
                *e = f64::INFINITY;
            }
        }
    }
    err
}

/// A priori error of every element of `mesh` (see the module docs): the variation of the
/// reflected direct exitance over the element (if `opts.direct`), and infinity for elements
/// that a contact line crosses (if `opts.contact`). Returns the errors and the rays cast.
pub fn a_priori_errors(scene: &Scene, mesh: &Mesh, rays: &SceneRays, opts: &Options) -> (Vec<f64>, u64) {
    let mut nrays = 0;
    let samples = opts.direct.then(|| {
        let (s, r) = direct_samples(scene, mesh, rays, opts);
        nrays += r;
        s
    });
    let receivers = opts.contact.then(|| Receivers::compute(scene, mesh, rays));
    nrays += receivers.as_ref().map_or(0, |r| r.rays);
    let scale = samples.as_ref().map_or(1.0, |s| mean_exitance(scene, mesh, |i| s[i].centre));
    (errors_from(samples.as_deref(), receivers.as_ref(), mesh.len(), scale), nrays)
}

/// A priori refinement of `refiner`'s mesh: rounds of estimating ([`a_priori_errors`], on
/// the new leaves only) and splitting, until no leaf is over the threshold, every one over
/// it is at `opts.max_depth`, or `opts.max_elements` is reached: one level per round, the
/// largest errors first when the limit cuts a round short. Returns what it did and the
/// rays cast. [`Progress::should_stop`] is polled before every round: after an interrupt the
/// rounds done so far are kept and the caller decides (the pipeline then cancels).
pub fn refine_a_priori(
    scene: &Scene,
    rays: &SceneRays,
    refiner: &mut Refiner,
    opts: &Options,
    progress: &dyn Progress,
) -> (PassStats, u64) {
    let n0 = refiner.mesh().len();
    let mut total = PassStats { elements_before: n0, elements_after: n0, ..Default::default() };
    let mut nrays = 0;
    if !opts.direct && !opts.contact {
        return (total, 0);
    }
    let mut cache: HashMap<u32, f64> = HashMap::new();
    let mut scale = None;
    // Which side of each two-sided pair is air depends on the scene alone: found once.
    let sides = opts.contact.then(|| Receivers::sides(scene, rays));
    for _ in 0..opts.max_depth {
        if progress.should_stop() {
            break;
        }
        let (leaf_mesh, ids) = refiner.leaf_mesh();
        let new: Vec<usize> = (0..ids.len()).filter(|&i| !cache.contains_key(&ids[i])).collect();
        let sub = Mesh {
            elements: new.iter().map(|&i| leaf_mesh.elements[i]).collect(),
            patches: Vec::new(),
            ..leaf_mesh
        };
        let samples = opts.direct.then(|| {
            let (s, r) = direct_samples(scene, &sub, rays, opts);
            nrays += r;
            s
        });
        // The scale is the mean over the whole first (uniform) mesh, kept for later rounds.
        let sc = *scale.get_or_insert_with(|| samples.as_ref().map_or(1.0, |s| mean_exitance(scene, &sub, |i| s[i].centre)));
        let receivers = sides.as_ref().map(|sd| Receivers::compute_given(scene, &sub, rays, sd.clone(), &crate::NoProgress));
        nrays += receivers.as_ref().map_or(0, |r| r.rays);
        for (k, e) in errors_from(samples.as_deref(), receivers.as_ref(), sub.len(), sc).into_iter().enumerate() {
            cache.insert(ids[new[k]], e);
        }
        let pairs: Vec<(u32, f64)> = ids.iter().map(|&l| (l, cache[&l])).collect();
        let s = refiner.refine_leaves(&pairs, opts);
        total.splits += s.splits;
        total.over_threshold = s.over_threshold;
        total.capped |= s.capped;
        total.elements_after = s.elements_after;
        if s.splits == 0 {
            break;
        }
    }
    (total, nrays)
}

/// A posteriori error of every element: the largest difference, in units of the scene's
/// mean exitance, between the element's reflected indirect exitance `ρ_i·(F·(B − E))_i`
/// and the values reconstructed at its vertices. `indirect` is `(F·(B − E))_i` per element
/// and `radiosity` the solved `B` (for the scale).
pub fn a_posteriori_errors(scene: &Scene, mesh: &Mesh, indirect: &[Rgb], radiosity: &[Rgb]) -> Vec<f64> {
    let rho: Vec<Rgb> = mesh
        .elements
        .iter()
        .map(|e| {
            let m = &scene.materials[scene.polygons[e.patch as usize].material as usize];
            if m.base_texture.is_some() {
                let (c, n) = e.corners(&mesh.positions);
                scene.surface_means(e.patch as usize, &c[..n]).0
            } else {
                m.reflectance
            }
        })
        .collect();
    let reflected: Vec<Rgb> = indirect.iter().zip(&rho).map(|(h, r)| *h * *r).collect();
    let vertex = crate::reconstruct::vertex_radiosity(scene, mesh, &reflected);
    let mean = mean_exitance(scene, mesh, |i| luminance(radiosity[i]));
    mesh.elements
        .iter()
        .enumerate()
        .map(|(i, e)| {
            (0..e.vertex_count())
                .map(|k| luminance((vertex[e.vertices[k] as usize] - reflected[i]).abs()))
                .fold(0.0, f64::max)
                / mean
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::mesh_uniform;
    use crate::scene::builtin;

    /// Every element edge inside a patch is shared by exactly two elements with the same end
    /// vertices, or lies on the patch boundary; no vertex of the patch lies strictly inside
    /// an element edge.
    pub(crate) fn assert_conforming(scene: &Scene, mesh: &Mesh) {
        for (pi, pe) in mesh.patches.iter().enumerate() {
            let els = &mesh.elements[pe.first as usize..(pe.first + pe.count) as usize];
            let mut count: HashMap<(u32, u32), u32> = HashMap::new();
            let mut verts = Vec::new();
            for e in els {
                assert_eq!(e.patch as usize, pi);
                let n = e.vertex_count();
                for k in 0..n {
                    let (a, b) = (e.vertices[k], e.vertices[(k + 1) % n]);
                    *count.entry((a.min(b), a.max(b))).or_default() += 1;
                    verts.push(a);
                }
            }
            verts.sort_unstable();
            verts.dedup();
            let poly = &scene.polygons[pi];
            let on_boundary = |p: DVec3| {
                let v = &poly.vertices;
                (0..v.len()).any(|k| dist_to_segment(p, v[k], v[(k + 1) % v.len()]) < 1e-9 * (1.0 + p.length()))
            };
            for (&(a, b), &c) in &count {
                let (pa, pb) = (mesh.positions[a as usize], mesh.positions[b as usize]);
                assert!(c <= 2, "patch {pi}: edge {a}-{b} used {c} times");
                if c == 1 {
                    assert!(
                        on_boundary(pa) && on_boundary(pb) && on_boundary(0.5 * (pa + pb)),
                        "patch {pi}: edge {pa}–{pb} has one element and is not on the patch boundary"
                    );
                }
                for &v in &verts {
                    if v == a || v == b {
                        continue;
                    }
                    let p = mesh.positions[v as usize];
                    let d = dist_to_segment(p, pa, pb);
                    let len = (pb - pa).length();
                    let t = (p - pa).dot(pb - pa) / (len * len);
                    assert!(
                        !(d < 1e-9 * len && t > 1e-9 && t < 1.0 - 1e-9),
                        "patch {pi}: vertex {v} at {p} lies inside edge {pa}–{pb} (a T-vertex)"
                    );
                }
            }
        }
    }

    fn dist_to_segment(p: DVec3, a: DVec3, b: DVec3) -> f64 {
        let ab = b - a;
        let t = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
        (a + ab * t - p).length()
    }

    fn assert_invariants(scene: &Scene, mesh: &Mesh) {
        for (pi, p) in scene.polygons.iter().enumerate() {
            let pe = mesh.patches[pi];
            let els = &mesh.elements[pe.first as usize..(pe.first + pe.count) as usize];
            let a: f64 = els.iter().map(|e| e.area).sum();
            assert!((a - p.area).abs() < 1e-9 * p.area, "patch {pi}: area {a} vs {}", p.area);
            for e in els {
                let (c, n) = e.corners(&mesh.positions);
                // Convex, counter-clockwise about the patch normal, in the patch plane.
                for k in 0..n {
                    let (x, y, z) = (c[k], c[(k + 1) % n], c[(k + 2) % n]);
                    assert!((y - x).cross(z - y).dot(p.normal) > 0.0, "patch {pi}: element not CCW/convex");
                    assert!((x - p.vertices[0]).dot(p.normal).abs() < 1e-9 * scene.diagonal());
                }
                assert_eq!(e.normal, p.normal);
            }
        }
        let total: u32 = mesh.patches.iter().map(|p| p.count).sum();
        assert_eq!(total as usize, mesh.len());
    }

    #[test]
    fn refining_anywhere_keeps_the_mesh_conforming_and_the_area() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let mesh = mesh_uniform(&scene, 100.0);
        let mut r = Refiner::new(&scene, &mesh);
        assert_eq!(r.mesh().len(), mesh.len());
        let opts = Options { threshold: 0.5, max_depth: 4, max_elements: Some(100_000), ..Default::default() };
        // Pseudo-random patterns of marked elements, three passes deep: every mark splits.
        for pass in 0..3u64 {
            let errs: Vec<f64> =
                (0..r.mesh().len()).map(|i| if crate::sampling::mix64(i as u64 ^ (pass << 32)) % 5 == 0 { 1.0 } else { 0.0 }).collect();
            let marked = errs.iter().filter(|e| **e > 0.5).count();
            let before = r.mesh().len();
            let s = r.refine(&errs, &opts);
            assert!(s.splits > 0 && r.mesh().len() > before + 2 * marked, "{s:?}");
            assert_invariants(&scene, r.mesh());
            assert_conforming(&scene, r.mesh());
        }
        // Transition elements exist (otherwise the test would not test them) and the
        // depths differ by at most one across every shared vertex of a patch... checked via
        // the T-vertex test above; here: the depth range is what was asked for.
        let d = r.depths();
        assert_eq!(*d.iter().max().unwrap(), 3);
        assert!(r.mesh().elements.iter().any(|e| e.vertex_count() == 3 && scene.polygons[e.patch as usize].vertices.len() == 4));
    }

    #[test]
    fn element_limit_is_hard_and_keeps_the_largest_errors() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let mesh = mesh_uniform(&scene, 100.0);
        let n0 = mesh.len();
        let mut r = Refiner::new(&scene, &mesh);
        // Errors grow with the element index; only the last ones fit.
        let errs: Vec<f64> = (0..n0).map(|i| 1.0 + i as f64).collect();
        let opts = Options { threshold: 0.5, max_depth: 2, max_elements: Some(n0 + 60), ..Default::default() };
        let s = r.refine(&errs, &opts);
        assert!(s.capped);
        assert!(r.mesh().len() <= n0 + 60 && r.mesh().len() > n0 + 30, "{s:?}");
        assert_conforming(&scene, r.mesh());
        // The element with the largest error was split; the smallest was not.
        let d = r.depths();
        let last_patch = scene.polygons.len() - 1;
        let pe = r.mesh().patches[last_patch];
        assert!(d[(pe.first + pe.count - 1) as usize] == 1);
        assert_eq!(d[0], 0);
    }

    #[test]
    fn coplanar_patches_with_matching_grids_stay_conforming_across() {
        // Two coplanar quads of one material sharing an edge, with matching grids: a split
        // on one side makes the other side conform too.
        use crate::scene::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
        let v = |x: f64, z: f64| DVec3::new(x, 0.0, z);
        let desc = SceneDesc {
            name: "two".into(),
            materials: vec![MaterialDesc::diffuse("grey", Rgb::splat(0.5))],
            objects: vec![ObjectDesc { name: "a".into(), loc: None }, ObjectDesc { name: "b".into(), loc: None }],
            polygons: vec![
                PolygonDesc { uvs: Vec::new(), vertices: vec![v(0., 0.), v(0., 1.), v(1., 1.), v(1., 0.)], material: 0, object: 0, loc: None },
                PolygonDesc { uvs: Vec::new(), vertices: vec![v(1., 0.), v(1., 1.), v(2., 1.), v(2., 0.)], material: 0, object: 1, loc: None },
            ],
            ..Default::default()
        };
        let scene = Scene::from_desc(desc).unwrap();
        let mesh = mesh_uniform(&scene, 0.5);
        let mut r = Refiner::new(&scene, &mesh);
        // Split the element of patch 0 at the common edge x = 1 twice.
        let opts = Options { threshold: 0.5, max_depth: 2, max_elements: Some(1000), ..Default::default() };
        for _ in 0..2 {
            let errs: Vec<f64> = r
                .mesh()
                .elements
                .iter()
                .map(|e| {
                    // The element of patch 0 that holds the point (0.99, 0, 0.1).
                    let (c, n) = e.corners(&r.mesh().positions);
                    let (lo, hi) = c[..n].iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), p| (l.min(*p), h.max(*p)));
                    let inside = (lo.x..=hi.x).contains(&0.99) && (lo.z..=hi.z).contains(&0.1);
                    if e.patch == 0 && inside { 1.0 } else { 0.0 }
                })
                .collect();
            r.refine(&errs, &opts);
        }
        // Welded (by position) vertices of patch 1 on x = 1 include every vertex of patch 0
        // there, and the other way round: no T-vertex across the common edge.
        let on_edge = |p: u32| -> Vec<i64> {
            let pe = r.mesh().patches[p as usize];
            let mut zs: Vec<i64> = r.mesh().elements[pe.first as usize..(pe.first + pe.count) as usize]
                .iter()
                .flat_map(|e| e.vertices[..e.vertex_count()].to_vec())
                .map(|v| r.mesh().positions[v as usize])
                .filter(|p| (p.x - 1.0).abs() < 1e-12)
                .map(|p| (p.z * 1e6).round() as i64)
                .collect();
            zs.sort_unstable();
            zs.dedup();
            zs
        };
        assert_eq!(on_edge(0), on_edge(1));
        assert!(on_edge(0).len() > 3, "{:?}", on_edge(0));
        assert_conforming(&scene, r.mesh());
    }

    #[test]
    fn a_priori_refinement_stops_on_interrupt() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let rays = SceneRays::new(&scene.polygons);
        let mesh = mesh_uniform(&scene, 60.0);
        let mut r = Refiner::new(&scene, &mesh);
        let stop = crate::progress::StopFlag::default();
        stop.stop();
        let (stats, nrays) = refine_a_priori(&scene, &rays, &mut r, &Options::default(), &stop);
        // Interrupted before the first round: no rays, no splits, the uniform mesh kept.
        assert_eq!((stats.splits, nrays, r.mesh().len()), (0, 0, mesh.len()), "{stats:?}");
    }

    #[test]
    fn cornell_floor_is_refined_at_the_block_bases_and_shadows_not_where_light_is_smooth() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let rays = SceneRays::new(&scene.polygons);
        let mesh = mesh_uniform(&scene, 60.0);
        let mut r = Refiner::new(&scene, &mesh);
        let opts = Options::default();
        let (stats, nrays) = refine_a_priori(&scene, &rays, &mut r, &opts, &crate::NoProgress);
        assert!(nrays > 0 && stats.splits > 0, "{stats:?}");
        assert!(r.mesh().len() <= opts.limit(mesh.len()));
        assert_invariants(&scene, r.mesh());
        assert_conforming(&scene, r.mesh());
        let depth = r.depths();
        let floor = r.mesh().patches[0];
        let floor_els = floor.first as usize..(floor.first + floor.count) as usize;
        // Distance (in the floor plane) from a point to the base outline of a block.
        let base = |name: &str| -> Vec<DVec3> {
            let o = scene.objects.iter().position(|o| o.name == name).unwrap() as u32;
            scene.polygons.iter().find(|p| p.object == o).unwrap().vertices.iter().map(|v| DVec3::new(v.x, 0.0, v.z)).collect()
        };
        let outline = |v: &[DVec3], p: DVec3| (0..v.len()).map(|k| dist_to_segment(p, v[k], v[(k + 1) % v.len()])).fold(f64::INFINITY, f64::min);
        let (short, tall) = (base("short_top"), base("tall_top"));
        let (mut contact, mut contact_refined) = (0, 0);
        for i in floor_els.clone() {
            let e = &r.mesh().elements[i];
            let size = e.area.sqrt();
            if outline(&short, e.centroid).min(outline(&tall, e.centroid)) < 0.3 * size {
                contact += 1;
                contact_refined += (depth[i] >= 1) as usize;
            }
        }
        assert!(contact >= 20 && contact_refined == contact, "{contact_refined} of {contact} floor elements on the block bases refined");
        // Front right: lit by the whole light past both blocks, no shadow, no contact.
        let smooth: Vec<usize> = floor_els
            .clone()
            .filter(|&i| {
                let c = r.mesh().elements[i].centroid;
                (430.0..540.0).contains(&c.x) && (10.0..110.0).contains(&c.z)
            })
            .collect();
        assert!(smooth.len() >= 4 && smooth.iter().all(|&i| depth[i] == 0), "smooth corner refined");
        // The blocks' shadows fall between and in front of them: most refined floor area lies
        // within 150 mm of a block.
        let (mut near, mut all) = (0.0, 0.0);
        for i in floor_els {
            if depth[i] >= 1 {
                let e = &r.mesh().elements[i];
                all += e.area;
                if outline(&short, e.centroid).min(outline(&tall, e.centroid)) < 150.0 {
                    near += e.area;
                }
            }
        }
        assert!(near > 0.8 * all, "refined floor area near the blocks {near} of {all}");
    }

    #[test]
    fn furnace_is_not_refined_and_refined_meshes_keep_b_exact() {
        use crate::form_factor;
        use crate::solve::{self, Solver, System};
        let (rho, radiance) = (0.5, 1.0);
        let scene = Scene::from_desc(builtin::furnace(rho, radiance)).unwrap();
        let rays = SceneRays::new(&scene.polygons);
        let mesh = mesh_uniform(&scene, 0.34);
        let mut r = Refiner::new(&scene, &mesh);
        // Uniformly lit: direct irradiance is E everywhere (every wall emits alike), nothing
        // to refine.
        let (errs, _) = a_priori_errors(&scene, &mesh, &rays, &Options::default());
        let worst = errs.iter().cloned().fold(0.0, f64::max);
        assert!(worst < 1e-9, "furnace a priori error {worst}");
        let (stats, _) = refine_a_priori(&scene, &rays, &mut r, &Options::default(), &crate::NoProgress);
        assert_eq!((stats.splits, r.mesh().len()), (0, mesh.len()), "{stats:?}");
        // Refined anyway (every third element, twice): still B = E / (1 − ρ) everywhere.
        let opts = Options { threshold: 0.5, max_depth: 2, max_elements: Some(10_000), ..Default::default() };
        for pass in 0..2u64 {
            let errs: Vec<f64> = (0..r.mesh().len()).map(|i| ((i as u64 + pass) % 3 == 0) as u8 as f64).collect();
            r.refine(&errs, &opts);
        }
        let m = r.mesh();
        assert!(m.len() > 2 * mesh.len());
        assert_conforming(&scene, m);
        let rec = Receivers::compute(&scene, m, &rays);
        let (f, _) = form_factor::compute(&scene, m, &rays, &rec, &form_factor::Options::default(), &crate::NoProgress).unwrap();
        let (rh, em): (Vec<Rgb>, Vec<Rgb>) = m
            .elements
            .iter()
            .map(|e| {
                let mat = &scene.materials[scene.polygons[e.patch as usize].material as usize];
                (mat.reflectance, mat.exitance())
            })
            .unzip();
        let area = rec.open_areas(m);
        let system = System { transport: &f, reflectance: &rh, emission: &em, area: &area };
        let sopts = solve::Options { tolerance: 1e-12, ..Default::default() };
        let sol = solve::solve(Solver::Jacobi, &system, &sopts, &crate::NoProgress).unwrap();
        let expect = std::f64::consts::PI * radiance / (1.0 - rho);
        for b in &sol.radiosity {
            assert!((*b - Rgb::splat(expect)).abs().max_element() <= 1e-6 * expect, "{b} vs {expect}");
        }
        // ... and the a posteriori estimate sees nothing to refine either.
        let h = crate::pipeline::indirect_irradiance(&scene, m, &f, &sol);
        let errs = a_posteriori_errors(&scene, m, &h, &sol.radiosity);
        assert!(errs.iter().all(|e| *e < 1e-4), "{:?}", errs.iter().cloned().fold(0.0, f64::max));
    }
}
