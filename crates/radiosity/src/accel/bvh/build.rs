//! Construction of the 8-wide BVH: top-down binned SAH (Wald 2007, "On fast construction of
//! SAH-based bounding volume hierarchies"; MacDonald & Booth 1990 for the cost model),
//! building wide nodes directly the way Embree does (Wald et al. 2014): a node starts as one
//! set of triangles and repeatedly splits the child of largest surface area with its best
//! binned-SAH plane until it has eight children or none is worth splitting; each child then
//! becomes a leaf or, recursively, a node. Children of large sets are built in parallel
//! (rayon), and the binning of large sets is itself split over threads.
//!
//! Sets of at most [`SWEEP_MAX`] triangles are split by an exact sweep over all object
//! splits along each axis (the "full sweep" SAH of MacDonald & Booth, affordable near the
//! leaves) instead of bins.
//!
//! Costs count triangle tests in packets of four (`⌈n/4⌉`, Embree's "block size"), so the
//! SAH prefers leaves that fill whole packets. Sets of up to [`MIN_LEAF`] triangles always
//! become leaves; up to [`MAX_LEAF`] when the SAH says a leaf is cheaper. When all
//! centroids of a set coincide (no plane separates them), or the tree gets deeper than
//! [`MAX_SAH_DEPTH`] wide levels, the set is split at its object median instead, which
//! bounds the depth on any input. Triangles with a non-finite coordinate are left out: no
//! ray can hit them.

use glam::Vec3;
use rayon::prelude::*;

use super::layout::{leaf_ref, ChildRef, Node, TriPacket, Unit, MAX_UNITS, NODE_UNITS, PACKET, WIDTH};

/// Bins per axis.
const BINS: usize = 32;
/// Sets this small get an exact SAH sweep over every object split instead of bins.
const SWEEP_MAX: usize = 32;
/// Sets this small always become one leaf.
const MIN_LEAF: usize = 4;
/// The largest leaf (the SAH decides between `MIN_LEAF` and this).
const MAX_LEAF: usize = 8;
/// Cost of visiting a node relative to testing one packet of triangles.
const TRAV_COST: f32 = 1.0;
/// Below this many triangles a subtree is built on the current thread.
const PARALLEL_MIN: usize = 4096;
/// Above this many triangles a set is binned in parallel chunks.
const PARALLEL_BIN_MIN: usize = 1 << 16;
/// Wide levels built by SAH; deeper sets are split at their object median.
const MAX_SAH_DEPTH: usize = 40;

#[derive(Clone, Copy, Debug)]
struct Aabb {
    lo: Vec3,
    hi: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb { lo: Vec3::splat(f32::INFINITY), hi: Vec3::splat(f32::NEG_INFINITY) };

    #[inline]
    fn grow(&mut self, p: Vec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    #[inline]
    fn merge(&mut self, b: &Aabb) {
        self.lo = self.lo.min(b.lo);
        self.hi = self.hi.max(b.hi);
    }

    /// Half the surface area (the SAH only compares ratios).
    #[inline]
    fn half_area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// A triangle during the build: its bounds and input index.
#[derive(Clone, Copy, Debug)]
struct PrimRef {
    lo: Vec3,
    hi: Vec3,
    id: u32,
}

impl PrimRef {
    /// Twice the centroid (the factor cancels everywhere).
    #[inline]
    fn c2(&self) -> Vec3 {
        self.lo + self.hi
    }
}

/// Bounds of a set of references and of their (doubled) centroids.
#[derive(Clone, Copy, Debug)]
struct SetBounds {
    geom: Aabb,
    cent: Aabb,
}

impl SetBounds {
    const EMPTY: SetBounds = SetBounds { geom: Aabb::EMPTY, cent: Aabb::EMPTY };

    #[inline]
    fn add(&mut self, r: &PrimRef) {
        self.geom.lo = self.geom.lo.min(r.lo);
        self.geom.hi = self.geom.hi.max(r.hi);
        self.cent.grow(r.c2());
    }

    fn merge(mut self, b: SetBounds) -> SetBounds {
        self.geom.merge(&b.geom);
        self.cent.merge(&b.cent);
        self
    }

    fn of(refs: &[PrimRef]) -> SetBounds {
        let mut b = SetBounds::EMPTY;
        for r in refs {
            b.add(r);
        }
        b
    }
}

/// Packets needed for `n` triangles.
#[inline]
fn blocks(n: usize) -> f32 {
    n.div_ceil(PACKET) as f32
}

/// How a set is divided in two.
#[derive(Clone, Copy, Debug)]
enum Plan {
    /// Centroids in bins `0..=bin` of `axis` go left.
    Sah { axis: usize, bin: usize, origin: f32, scale: f32 },
    /// The first `left` references in centroid order along `axis` go left.
    Sweep { axis: usize, left: usize },
    /// Object median along the longest centroid axis.
    Median,
}

/// A contiguous range of references being built.
#[derive(Clone, Copy, Debug)]
struct Set {
    /// Range in the reference array.
    start: usize,
    end: usize,
    bounds: SetBounds,
}

impl Set {
    fn len(&self) -> usize {
        self.end - self.start
    }
}

/// Per-axis bins: bounds and counts.
#[derive(Clone, Copy)]
struct Bins {
    bounds: [[Aabb; BINS]; 3],
    count: [[u32; BINS]; 3],
}

impl Bins {
    fn new() -> Bins {
        Bins { bounds: [[Aabb::EMPTY; BINS]; 3], count: [[0; BINS]; 3] }
    }

    fn add_all(&mut self, refs: &[PrimRef], origin: Vec3, scale: Vec3) {
        for r in refs {
            let b = ((r.c2() - origin) * scale).to_array();
            for (axis, b) in b.into_iter().enumerate() {
                let i = (b as usize).min(BINS - 1);
                self.count[axis][i] += 1;
                let bb = &mut self.bounds[axis][i];
                bb.lo = bb.lo.min(r.lo);
                bb.hi = bb.hi.max(r.hi);
            }
        }
    }

    fn merge(mut self, o: Bins) -> Bins {
        for axis in 0..3 {
            for i in 0..BINS {
                self.count[axis][i] += o.count[axis][i];
                self.bounds[axis][i].merge(&o.bounds[axis][i]);
            }
        }
        self
    }
}

#[inline]
fn bin_of(c: f32, origin: f32, scale: f32) -> usize {
    (((c - origin) * scale) as usize).min(BINS - 1)
}

/// Orders references by centroid along `axis` (ties by input index, so the order is the
/// same every time).
fn sort_along(refs: &mut [PrimRef], axis: usize) {
    refs.sort_unstable_by(|x, y| x.c2()[axis].total_cmp(&y.c2()[axis]).then(x.id.cmp(&y.id)));
}

/// The best object split of a small set by an exact sweep over each axis.
fn sweep_sah(refs: &[PrimRef]) -> Option<(f32, Plan)> {
    let n = refs.len();
    let mut sorted = [PrimRef { lo: Vec3::ZERO, hi: Vec3::ZERO, id: 0 }; SWEEP_MAX];
    let sorted = &mut sorted[..n];
    let mut right = [0f32; SWEEP_MAX];
    let mut best: Option<(f32, Plan)> = None;
    for axis in 0..3 {
        sorted.copy_from_slice(refs);
        sort_along(sorted, axis);
        let mut acc = Aabb::EMPTY;
        for i in (1..n).rev() {
            acc.merge(&Aabb { lo: sorted[i].lo, hi: sorted[i].hi });
            right[i] = acc.half_area() * blocks(n - i);
        }
        let mut acc = Aabb::EMPTY;
        for i in 0..n - 1 {
            acc.merge(&Aabb { lo: sorted[i].lo, hi: sorted[i].hi });
            let cost = acc.half_area() * blocks(i + 1) + right[i + 1];
            if cost < best.map_or(f32::INFINITY, |b| b.0) {
                best = Some((cost, Plan::Sweep { axis, left: i + 1 }));
            }
        }
    }
    best
}

/// The best SAH split of a set: (cost = Σ half-area × blocks, plan) by an exact sweep for
/// small sets and by binning otherwise; `None` when all centroids coincide.
fn find_sah(refs: &[PrimRef], b: &SetBounds) -> Option<(f32, Plan)> {
    if b.cent.lo == b.cent.hi {
        return None;
    }
    if refs.len() <= SWEEP_MAX {
        return sweep_sah(refs);
    }
    let ext = b.cent.hi - b.cent.lo;
    // Slightly under BINS so the largest centroid maps inside the last bin.
    let scale = Vec3::select(ext.cmpgt(Vec3::ZERO), (BINS as f32 * 0.99999) / ext, Vec3::ZERO);
    if scale == Vec3::ZERO || !scale.is_finite() {
        return None;
    }
    let origin = b.cent.lo;
    let bins = if refs.len() >= PARALLEL_BIN_MIN {
        refs.par_chunks(PARALLEL_BIN_MIN / 4)
            .map(|c| {
                let mut bins = Bins::new();
                bins.add_all(c, origin, scale);
                bins
            })
            .reduce(Bins::new, Bins::merge)
    } else {
        let mut bins = Bins::new();
        bins.add_all(refs, origin, scale);
        bins
    };
    let mut best: Option<(f32, Plan)> = None;
    for axis in 0..3 {
        if scale[axis] == 0.0 {
            continue;
        }
        // Right-to-left sweep: cost of the right side starting at each bin.
        let mut right = [0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut n = 0usize;
        for i in (1..BINS).rev() {
            acc.merge(&bins.bounds[axis][i]);
            n += bins.count[axis][i] as usize;
            right[i] = if n == 0 { f32::INFINITY } else { acc.half_area() * blocks(n) };
        }
        let mut acc = Aabb::EMPTY;
        let mut n = 0usize;
        for i in 0..BINS - 1 {
            acc.merge(&bins.bounds[axis][i]);
            n += bins.count[axis][i] as usize;
            if n == 0 {
                continue;
            }
            let cost = acc.half_area() * blocks(n) + right[i + 1];
            if cost < best.map_or(f32::INFINITY, |b| b.0) {
                best = Some((cost, Plan::Sah { axis, bin: i, origin: origin[axis], scale: scale[axis] }));
            }
        }
    }
    best
}

/// Splits `refs` (a set with bounds `b`) by `plan`; returns the size of the left part and
/// the bounds of both parts. Both parts are non-empty.
fn partition(refs: &mut [PrimRef], b: &SetBounds, plan: Plan) -> (usize, SetBounds, SetBounds) {
    let mid = match plan {
        Plan::Sah { axis, bin, origin, scale } => {
            // Bounds of both sides are gathered as the elements are classified.
            let (mut lb, mut rb) = (SetBounds::EMPTY, SetBounds::EMPTY);
            let (mut i, mut j) = (0, refs.len());
            while i < j {
                let r = refs[i];
                if bin_of(r.c2()[axis], origin, scale) <= bin {
                    lb.add(&r);
                    i += 1;
                } else {
                    rb.add(&r);
                    j -= 1;
                    refs.swap(i, j);
                }
            }
            debug_assert!(i > 0 && i < refs.len());
            return (i, lb, rb);
        }
        Plan::Sweep { axis, left } => {
            sort_along(refs, axis);
            left
        }
        Plan::Median => {
            let axis = (b.cent.hi - b.cent.lo).max_position();
            let mid = refs.len() / 2;
            refs.select_nth_unstable_by(mid, |x, y| x.c2()[axis].total_cmp(&y.c2()[axis]));
            mid
        }
    };
    debug_assert!(mid > 0 && mid < refs.len());
    (mid, SetBounds::of(&refs[..mid]), SetBounds::of(&refs[mid..]))
}

/// What to do with a set: make it a leaf, or split it by a plan.
fn decide(refs: &[PrimRef], set: &Set, depth: usize) -> Option<Plan> {
    let n = set.len();
    if n <= MIN_LEAF {
        return None;
    }
    if depth > MAX_SAH_DEPTH {
        return if n <= MAX_LEAF { None } else { Some(Plan::Median) };
    }
    match find_sah(refs, &set.bounds) {
        None => (n > MAX_LEAF).then_some(Plan::Median),
        Some((cost, plan)) => {
            let area = set.bounds.geom.half_area();
            let leaf = area * blocks(n);
            let split = TRAV_COST * area + cost;
            if n <= MAX_LEAF && leaf <= split {
                None
            } else {
                Some(plan)
            }
        }
    }
}

/// A subtree before flattening.
enum Tmp {
    /// References `start..start + count`.
    Leaf { start: usize, count: usize },
    /// Children with their bounds.
    Node(Vec<(Aabb, Tmp)>),
}

/// Builds the subtree of `set`, whose references are `refs` (`refs[0]` is `set.start`),
/// known to need splitting by `plan`.
fn build_node(refs: &mut [PrimRef], set: Set, plan: Plan, depth: usize) -> Tmp {
    // (set, plan): plan `None` means "leaf"; the outer Option caches the decision.
    let mut kids: Vec<(Set, Option<Option<Plan>>)> = vec![(set, Some(Some(plan)))];
    let base = set.start;
    while kids.len() < WIDTH {
        let mut pick: Option<(usize, f32)> = None;
        for (i, (s, _)) in kids.iter().enumerate() {
            let a = s.bounds.geom.half_area();
            if s.len() > MIN_LEAF && pick.is_none_or(|p| a > p.1) {
                pick = Some((i, a));
            }
        }
        let Some((i, _)) = pick else { break };
        let (s, decision) = kids[i];
        let local = &mut refs[s.start - base..s.end - base];
        // Inside a node a split costs no extra node visit: split every set larger than
        // MIN_LEAF (as Embree does), even one the SAH would keep as a leaf.
        let plan = match decision {
            Some(Some(p)) => p,
            _ if depth > MAX_SAH_DEPTH => Plan::Median,
            _ => find_sah(local, &s.bounds).map_or(Plan::Median, |p| p.1),
        };
        let (mid, lb, rb) = partition(local, &s.bounds, plan);
        kids[i] = (Set { start: s.start, end: s.start + mid, bounds: lb }, None);
        kids.push((Set { start: s.start + mid, end: s.end, bounds: rb }, None));
    }
    kids.sort_by_key(|k| k.0.start);
    // Hand each child its own slice of the references.
    let mut jobs = Vec::with_capacity(kids.len());
    let mut rest = refs;
    for (s, d) in kids {
        let (mine, tail) = rest.split_at_mut(s.len());
        rest = tail;
        jobs.push((mine, s, d));
    }
    let build_kid = |(mine, s, d): (&mut [PrimRef], Set, Option<Option<Plan>>)| {
        let plan = d.unwrap_or_else(|| decide(mine, &s, depth + 1));
        let sub = match plan {
            None => Tmp::Leaf { start: s.start, count: s.len() },
            Some(p) => build_node(mine, s, p, depth + 1),
        };
        (s.bounds.geom, sub)
    };
    if set.len() >= PARALLEL_MIN {
        Tmp::Node(jobs.into_par_iter().map(build_kid).collect())
    } else {
        Tmp::Node(jobs.into_iter().map(build_kid).collect())
    }
}

/// Appends `tmp` (a node) to `units`, then the packets of its leaf children, then its
/// interior children's subtrees; returns the node's unit index.
fn flatten(
    tmp: &[(Aabb, Tmp)],
    refs: &[PrimRef],
    tris: &[[Vec3; 3]],
    units: &mut Vec<Unit>,
    nodes: &mut usize,
) -> ChildRef {
    *nodes += 1;
    let at = units.len();
    units.extend([Unit::default(); NODE_UNITS]);
    let mut node = Node::EMPTY;
    for (slot, (b, kid)) in tmp.iter().enumerate() {
        if let Tmp::Leaf { start, count } = kid {
            let first = units.len();
            let chunks = refs[*start..start + count].chunks(PACKET);
            let n = chunks.len();
            for chunk in chunks {
                let mut p = TriPacket::EMPTY;
                for (lane, r) in chunk.iter().enumerate() {
                    p.set(lane, &tris[r.id as usize], r.id);
                }
                units.extend(p.to_units());
            }
            node.set(slot, b.lo, b.hi, leaf_ref(first, n));
        }
    }
    for (slot, (b, kid)) in tmp.iter().enumerate() {
        if let Tmp::Node(kids) = kid {
            let r = flatten(kids, refs, tris, units, nodes);
            node.set(slot, b.lo, b.hi, r);
        }
    }
    units[at..at + NODE_UNITS].copy_from_slice(&node.to_units());
    at as ChildRef
}

/// Builds the stored tree over `tris` (the root node at unit 0); empty when no triangle is
/// finite. Also returns the number of nodes.
pub(super) fn build(tris: &[[Vec3; 3]]) -> (Vec<Unit>, usize) {
    // Two units per triangle at most: 5 per packet of 4, 7 per node of 8 leaves.
    assert!(tris.len() <= MAX_UNITS / 2, "too many triangles for one BVH ({})", tris.len());
    let mut refs: Vec<PrimRef> = tris
        .par_iter()
        .enumerate()
        .filter(|(_, t)| t.iter().all(|p| p.is_finite()))
        .map(|(i, t)| PrimRef { lo: t[0].min(t[1]).min(t[2]), hi: t[0].max(t[1]).max(t[2]), id: i as u32 })
        .collect();
    if refs.is_empty() {
        return (Vec::new(), 0);
    }
    let bounds = refs
        .par_chunks(PARALLEL_BIN_MIN / 4)
        .map(SetBounds::of)
        .reduce(|| SetBounds::EMPTY, SetBounds::merge);
    let root = Set { start: 0, end: refs.len(), bounds };
    let tmp = match decide(&refs, &root, 0) {
        None => vec![(bounds.geom, Tmp::Leaf { start: 0, count: refs.len() })],
        Some(plan) => match build_node(&mut refs, root, plan, 0) {
            Tmp::Node(kids) => kids,
            Tmp::Leaf { .. } => unreachable!("build_node returns a node"),
        },
    };
    let mut units = Vec::with_capacity(refs.len() * 3 / 2 + NODE_UNITS);
    let mut nodes = 0;
    flatten(&tmp, &refs, tris, &mut units, &mut nodes);
    (units, nodes)
}
