//! Adaptive integration with exact shadows: the accuracy reference for thermal work
//! (after Walton 2002, "Calculation of obstructed view factors by adaptive integration",
//! NISTIR 6925 — the method of View3D).
//!
//! ```text
//! A_i F_ij = ∫_{A_i} F(dA_x → V_j(x)) dA_x,    V_j(x) = the part of A_j visible from x
//! ```
//!
//! - **Receiver, exactly.** For a point `x` of the sender, every polygon that could block
//!   is clipped to the pyramid with apex `x` over the receiver (and to the receiver's front
//!   half-space), projected from `x` onto the receiver's plane, and cut out of the
//!   receiver (2-D convex differences). `F(dA_x → V_j(x))` is then the contour integral
//!   ([`super::analytic::point_factor`]) over the visible convex pieces: exact for any number of partial
//!   occluders, with no visibility sampling.
//! - **Sender, adaptively.** The sender is split into triangles; each triangle carries a
//!   3×3 and a 4×4 collapsed Gauss–Legendre estimate, their difference is its error. The
//!   triangle with the largest error is cut into four until the total error is below
//!   `tolerance × A_i F_ij` (or `tolerance × 10⁻³ × A_i`, an absolute floor for tiny
//!   factors) or the evaluation budget is spent. Occluded pairs start from one level of
//!   subdivision so that both rules never see just one side of a shadow edge.
//! - **Unoccluded pairs** (no polygon meets the bounding box of the pair in front of both
//!   planes) take the exact contour integral ([`super::analytic`]), as View3D takes its
//!   analytic/line-integral path when nothing obstructs.
//!
//! - **Cost.** The few pairs deep in penumbra behind many occluders take most of the
//!   time. Each sender region sorts its occluders by the size of their shadow from its
//!   centroid, largest first, so the receiver is used up by few large cuts; an occluder
//!   well below the point is projected without the pyramid clip, and one whose shadow
//!   misses what is left is skipped; both rows of an expensive pair take its integral
//!   once ([`PairCache`]); the tolerance and the evaluation budget hold per pair, over all
//!   the sender's pieces, and pairs that stop at the budget are counted in a warning with
//!   their estimated error.
//!
//! Unlike View3D's 1AI/2AI, the inner factor is exact under partial occlusion, which is
//! where View3D's adaptive scheme (and every ray-sampled method) makes its largest
//! errors; the only approximation is the outer cubature, controlled by the tolerance.

use std::cmp::Ordering as CmpOrdering;
use std::collections::BinaryHeap;

use glam::{DVec2, DVec3};

use super::analytic;
use super::geom::{area2_2d, bounds_2d, bounds_3d, clip_halfspace, gauss_legendre, PieceSet, PlaneFrame};
use super::kernel::point_to_polygon_unsided;
use super::occluders::Occluders;
use super::{Context, RowSource};

/// Default relative tolerance.
pub const DEFAULT_TOLERANCE: f64 = 1e-5;
/// Default evaluation budget per element pair.
pub const DEFAULT_MAX_EVALUATIONS: usize = 50_000;

pub(crate) struct Rows<'a> {
    ctx: &'a Context<'a>,
    /// What casts shadows: the scene's polygons, coplanar neighbours merged
    /// ([`Occluders`]); `of[p]` is the occluder that polygon `p` is part of.
    occluders: Occluders,
    of: Vec<u32>,
    tree: PolyTree,
    /// [`Context::twins`]: they own their overlap, so another row sees it once (a
    /// two-sided box's bottom on the floor).
    twins: &'a [Vec<u32>],
    /// `A_i F_ij` of expensive pairs, kept by the first of the two rows that needs it
    /// for the other (see [`PairCache`]).
    cache: PairCache,
    /// Pairs that spent the evaluation budget before reaching the tolerance.
    budget: BudgetHits,
}

impl<'a> Rows<'a> {
    pub fn new(ctx: &'a Context<'a>) -> Self {
        // No polygon with a vertex behind another's plane ([`super::possible_occlusion`]):
        // every polygon bounds the convex region in front of all of them, so nothing can
        // come between two of them and the occluder search has nothing to look through
        // (two parallel plates cut into thousands of facets, a convex room).
        let never_occluded = super::possible_occlusion(ctx.scene).is_none();
        let polys = &ctx.scene.polygons;
        let verts: Vec<&[DVec3]> = polys.iter().map(|p| p.vertices.as_slice()).collect();
        let normals: Vec<DVec3> = polys.iter().map(|p| p.normal).collect();
        let (occluders, of) = Occluders::merge(&verts, &normals, &ctx.flatness, ctx.eps);
        let tree = PolyTree::new(if never_occluded { &[] } else { &occluders.verts });
        Rows { ctx, occluders, of, tree, twins: &ctx.twins, cache: PairCache::default(), budget: BudgetHits::default() }
    }

    /// `A_a F_ab` for row `a` and column `b` (on patches `patches`), computed by
    /// `compute`. Where both rows take the integral alike (`alike`: neither element
    /// partly covered; and neither patch with twins), it comes from the cache when the
    /// other row has computed it, and is kept for the other row if it was expensive (see
    /// [`PairCache`]).
    fn shared_pair(&self, a: u32, b: u32, patches: (u32, u32), alike: bool, s: &mut Scratch, compute: impl FnOnce(&mut Scratch) -> f64) -> f64 {
        if a == b || !alike || !self.twins[patches.0 as usize].is_empty() || !self.twins[patches.1 as usize].is_empty() {
            return compute(s);
        }
        let key = (a.min(b), a.max(b));
        if let Some(af) = self.cache.take(key) {
            return af;
        }
        let af = compute(s);
        if s.evals >= PairCache::MIN_EVALUATIONS {
            self.cache.put(key, af);
        }
        af
    }
}

/// Pairs whose integral stopped at the evaluation budget, with the sums of their values
/// and error estimates (`A_i F_ij`), for a warning that says how much it matters.
#[derive(Default)]
struct BudgetHits(std::sync::Mutex<(u64, f64, f64)>);

impl BudgetHits {
    fn record(&self, value: f64, err: f64) {
        let mut g = self.0.lock().unwrap_or_else(|e| e.into_inner());
        g.0 += 1;
        g.1 += value.abs();
        g.2 += err;
    }

    /// The warning, if any pair stopped at the budget. `total` is `Σ A_i` of the rows
    /// computed (the most `Σ A_i F_ij` can be), to put the error in proportion.
    fn warning(&self, max_evaluations: usize, total: f64) -> Option<String> {
        let (n, value, err) = *self.0.lock().unwrap_or_else(|e| e.into_inner());
        (n > 0).then(|| {
            format!(
                "adaptive form factors: {n} pair(s) stopped at the budget of {max_evaluations} evaluations before the \
                 tolerance, with estimated error {err:.3e} on A·F {value:.3e} ({:.2e} of the rows' total)",
                err / total.max(f64::MIN_POSITIVE)
            )
        })
    }
}

impl Rows<'_> {
    /// See [`BudgetHits::warning`].
    pub fn budget_warning(&self, total_area: f64) -> Option<String> {
        self.budget.warning(self.ctx.opts.adaptive_max_evaluations, total_area)
    }
}

impl PolygonRows<'_> {
    /// See [`BudgetHits::warning`].
    pub fn budget_warning(&self, total_area: f64) -> Option<String> {
        self.rows.budget_warning(total_area)
    }
}

/// Pair integrals shared by the two rows of a pair. `A_i F_ij = A_j F_ji` is one integral
/// (taken over the smaller element, [`Rows::pair`]), and row `j` would take it again;
/// when neither element is partly covered and neither polygon has coincident twins, both
/// rows integrate the same region over the same receiver, so the first keeps its result
/// for the second, which takes it out. Only pairs that cost at least
/// [`PairCache::MIN_EVALUATIONS`] integrand evaluations are kept (the few in deep
/// penumbra, which take most of the time), so the cache stays small.
#[derive(Default)]
struct PairCache {
    shards: [std::sync::Mutex<std::collections::HashMap<(u32, u32), f64>>; 16],
}

impl PairCache {
    const MIN_EVALUATIONS: usize = 1000;

    fn shard(&self, key: (u32, u32)) -> &std::sync::Mutex<std::collections::HashMap<(u32, u32), f64>> {
        &self.shards[(key.0 ^ key.1.rotate_left(7)) as usize % self.shards.len()]
    }

    fn take(&self, key: (u32, u32)) -> Option<f64> {
        self.shard(key).lock().unwrap_or_else(|e| e.into_inner()).remove(&key)
    }

    fn put(&self, key: (u32, u32), af: f64) {
        self.shard(key).lock().unwrap_or_else(|e| e.into_inner()).insert(key, af);
    }
}

/// Per-thread buffers.
#[derive(Default)]
pub(crate) struct Scratch {
    patches: Vec<u32>,
    cached: u32,
    occ: Vec<u32>,
    eval: EvalScratch,
    an: analytic::Scratch,
    heap: BinaryHeap<Region>,
    shaft: Vec<(DVec3, f64)>,
    rshaft: Vec<(DVec3, f64)>,
    /// The pair's first / second element where it is partly covered (see [`Rows::row`]).
    cover: (Option<u32>, Option<u32>),
    /// The element being integrated over, where it is partly covered.
    cover_sender: Option<u32>,
    /// The polygon integrated over when it is not the row's own (then its overlaps with
    /// lower-numbered twins do not send).
    twin_sender: Option<u32>,
    /// Integrand evaluations spent on the current pair.
    evals: usize,
    /// The occluder of the row's patch, and for each occluder it faces what lies between
    /// the two ([`Rows::between`]): `None` where one occluder hides all of one from the
    /// other.
    face: u32,
    faces: std::collections::HashMap<u32, Option<Vec<u32>>>,
    /// Where set, the possible occluders of the current pair are among these (instead of
    /// the whole tree).
    cands: Option<Vec<u32>>,
    near: Vec<u32>,
    si: Vec<DVec3>,
    sj: Vec<DVec3>,
}

#[derive(Default)]
struct EvalScratch {
    pieces: PieceSet,
    next: PieceSet,
    tmp2: [Vec<DVec2>; 2],
    a: Vec<DVec3>,
    b: Vec<DVec3>,
    shadow: Vec<DVec2>,
    lift: Vec<DVec3>,
    /// Pyramid side planes (normal through x) for the current point.
    sides: Vec<DVec3>,
}

/// The receiver of a pair: its polygon, plane frame, and the convex pieces that receive
/// (the polygon less what coincident twins own), in 2-D (counter-clockwise) and in 3-D.
struct Receiver<'p> {
    verts: &'p [DVec3],
    normal: DVec3,
    frame: PlaneFrame,
    start: PieceSet,
    pieces: Vec<Vec<DVec3>>,
    centroid: DVec3,
    eps2: f64,
    min_area: f64,
}

impl<'p> Receiver<'p> {
    fn new(verts: &'p [DVec3], normal: DVec3, cuts: &[&[DVec3]], s: &mut EvalScratch) -> Self {
        let frame = PlaneFrame::new(verts[0], normal);
        let mut outline: Vec<DVec2> = verts.iter().map(|v| frame.to_2d(*v)).collect();
        if area2_2d(&outline) < 0.0 {
            outline.reverse();
        }
        let area = 0.5 * area2_2d(&outline).abs();
        let size = area.sqrt();
        // Visible pieces below 1e-10 of the receiver are dropped: slivers between the
        // shadows of adjacent occluder faces (a shared edge projected twice, a hair apart)
        // otherwise multiply with every later cut, to thousands of pieces at one point.
        let (eps2, min_area) = (1e-12 * size, 1e-10 * area);
        let centroid = verts.iter().copied().sum::<DVec3>() / verts.len() as f64;
        let mut start = PieceSet::default();
        start.push(&outline);
        for c in cuts {
            // A twin lies in the receiver's plane: its outline there is exact.
            let mut cut: Vec<DVec2> = c.iter().map(|v| frame.to_2d(*v)).collect();
            if area2_2d(&cut) < 0.0 {
                cut.reverse();
            }
            start.subtract(&cut, eps2, min_area, &mut s.next, &mut s.tmp2);
            std::mem::swap(&mut start, &mut s.next);
        }
        let pieces = if cuts.is_empty() {
            vec![verts.to_vec()]
        } else {
            (0..start.len()).map(|k| start.piece(k).iter().map(|q| frame.to_3d(*q)).collect()).collect()
        };
        Receiver { verts, normal, frame, start, pieces, centroid, eps2, min_area }
    }
}

impl RowSource for Rows<'_> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        Scratch { cached: u32::MAX, face: u32::MAX, ..Default::default() }
    }

    fn row(&self, i: usize, s: &mut Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
        let ctx = self.ctx;
        let mesh = ctx.mesh;
        let ei = &mesh.elements[i];
        if s.cached != ei.patch {
            s.cached = ei.patch;
            ctx.facing_patches(ei.patch, &mut s.patches);
        }
        let (ci, ni) = ctx.corners(i);
        let ci = &ci[..ni];
        // The solvers want the factor of the open part (coverage): pieces of a partly
        // covered element that lie inside a solid are left out of the integration over it,
        // and the row is divided by the open area.
        let open = |e: usize| ctx.receivers.open_fraction.get(e).copied().unwrap_or(1.0);
        let partly = |f: f64| f > 0.0 && f < 1.0;
        let oi = open(i);
        let area_i = if partly(oi) { ei.area * oi } else { ei.area };
        let patches = std::mem::take(&mut s.patches);
        let face_i = self.of[ei.patch as usize];
        if s.face != face_i {
            s.face = face_i;
            s.faces.clear();
        }
        for &q in &patches {
            let pe = mesh.patches[q as usize];
            // What can come between any element of this patch and any of `q`'s.
            let face_j = self.of[q as usize];
            let between = match s.faces.get(&face_j) {
                Some(b) => b.clone(),
                None => {
                    // One list for both orders, so that the two rows of a pair integrate it alike
                    // (reciprocity to the last bit where the pair is cached or computed twice).
                    let b = self.between(face_i.min(face_j), face_i.max(face_j), s);
                    s.faces.insert(face_j, b.clone());
                    b
                }
            };
            let Some(between) = between else { continue };
            s.cands = Some(between);
            for j in pe.first..pe.first + pe.count {
                let ej = &mesh.elements[j as usize];
                let (cj, nj) = ctx.corners(j as usize);
                let oj = open(j as usize);
                s.cover = (partly(oi).then_some(i as u32), partly(oj).then_some(j));
                let pair = |s: &mut Scratch| self.pair(ci, ei.normal, ei.patch, &cj[..nj], ej.normal, q, s);
                let af = self.shared_pair(i as u32, j, (ei.patch, q), !partly(oi) && !partly(oj), s, pair);
                if af != 0.0 {
                    out.push((j, af / area_i));
                }
            }
        }
        s.cands = None;
        s.patches = patches;
        0
    }
}

/// Adaptive rows over whole polygons (see [`super::for_each_polygon_row`]).
pub(crate) struct PolygonRows<'a> {
    rows: Rows<'a>,
}

impl<'a> PolygonRows<'a> {
    pub fn new(ctx: &'a Context<'a>) -> Self {
        PolygonRows { rows: Rows::new(ctx) }
    }
}

impl RowSource for PolygonRows<'_> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        self.rows.scratch()
    }

    fn row(&self, p: usize, s: &mut Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
        let ctx = self.rows.ctx;
        ctx.facing_patches(p as u32, &mut s.patches);
        let polys = &ctx.scene.polygons;
        let pp = &polys[p];
        let patches = std::mem::take(&mut s.patches);
        for &q in &patches {
            let pq = &polys[q as usize];
            let pair = |s: &mut Scratch| self.rows.pair(&pp.vertices, pp.normal, p as u32, &pq.vertices, pq.normal, q, s);
            let af = self.rows.shared_pair(p as u32, q, (p as u32, q), true, s, pair);
            if af != 0.0 {
                out.push((q, af / pp.area));
            }
        }
        s.patches = patches;
        0
    }
}

impl Rows<'_> {
    /// `A_i F_ij` for polygon `pi` (on patch `patch_i`) and `pj`. The integral is taken
    /// over the smaller of the two (ties: the lower patch, then the first vertex), so that
    /// `A_i F_ij` and `A_j F_ji` are one and the same number: reciprocity is exact, and the
    /// sender's features (penumbrae) are large compared with it, where the cubature
    /// resolves them best.
    #[allow(clippy::too_many_arguments)]
    fn pair(&self, pi: &[DVec3], ni: DVec3, patch_i: u32, pj: &[DVec3], nj: DVec3, patch_j: u32, s: &mut Scratch) -> f64 {
        let (ai, aj) = (super::geom::area_3d(pi), super::geom::area_3d(pj));
        // A partly covered row element is always the one integrated over: its covered
        // pieces are left out, and the row is divided by its open area. Integrated over
        // the other element, the row also held the light that reaches its covered part,
        // and divided by the open area that came to 1/open times too much (raw row sums
        // up to 13 beside contacts, issue 9).
        let swap = s.cover.0.is_none()
            && match aj.total_cmp(&ai) {
                CmpOrdering::Less => true,
                CmpOrdering::Greater => false,
                CmpOrdering::Equal if patch_i != patch_j => patch_j < patch_i,
                CmpOrdering::Equal => (pj[0].x, pj[0].y, pj[0].z) < (pi[0].x, pi[0].y, pi[0].z),
            };
        s.cover_sender = if swap { s.cover.1 } else { s.cover.0 };
        s.evals = 0;
        s.twin_sender = (swap && !self.twins[patch_j as usize].is_empty()).then_some(patch_j);
        if swap {
            self.pair_directed(pj, nj, patch_j, pi, ni, patch_i, s)
        } else {
            self.pair_directed(pi, ni, patch_i, pj, nj, patch_j, s)
        }
    }

    /// `A_i F_ij`, integrating over `pi`.
    #[allow(clippy::too_many_arguments)]
    fn pair_directed(&self, pi: &[DVec3], ni: DVec3, patch_i: u32, pj: &[DVec3], nj: DVec3, patch_j: u32, s: &mut Scratch) -> f64 {
        let ctx = self.ctx;
        // Possible occluders: polygons meeting the pair's bounding box with some part in
        // front of both planes.
        let (lo1, hi1) = bounds_3d(pi);
        let (lo2, hi2) = bounds_3d(pj);
        let (lo, hi) = (lo1.min(lo2) - DVec3::splat(ctx.eps), hi1.max(hi2) + DVec3::splat(ctx.eps));
        s.occ.clear();
        let (oi, oj) = (pi[0], pj[0]);
        let polys = &ctx.scene.polygons;
        let occluders = &self.occluders.verts;
        let (own_i, own_j) = (self.of[patch_i as usize], self.of[patch_j as usize]);
        let eps = ctx.eps;
        let mut cands = s.cands.take();
        if let Some(c) = &cands {
            // The face pair's occluders near this pair: meeting its box, with a vertex in
            // front of both planes. One of them alone may hide the pair (most pairs in a
            // city), which needs no shaft.
            let mut near = std::mem::take(&mut s.near);
            near.clear();
            let bounds = &self.occluders.bounds;
            let (a, b) = (&mut s.eval.a, &mut s.eval.b);
            near.extend(c.iter().copied().filter(|&k| {
                let (blo, bhi) = bounds[k as usize];
                if !(blo.cmple(hi).all() && bhi.cmpge(lo).all()) {
                    return false;
                }
                let v = &occluders[k as usize];
                if v.iter().any(|p| ni.dot(*p - oi) > eps && nj.dot(*p - oj) > eps) {
                    return true;
                }
                if v.iter().all(|p| ni.dot(*p - oi) <= eps) || v.iter().all(|p| nj.dot(*p - oj) <= eps) {
                    return false;
                }
                // Some of it in front of both with no vertex there (an edge across the
                // corner of the two half-spaces).
                clip_halfspace(v, |p| ni.dot(p - oi) - eps, 0.0, a);
                clip_halfspace(a, |p| nj.dot(p - oj) - eps, 0.0, b);
                !b.is_empty()
            }));
            if !near.is_empty() {
                clip_halfspace(pi, |p| nj.dot(p - oj), eps, &mut s.si);
                clip_halfspace(pj, |p| ni.dot(p - oi), eps, &mut s.sj);
                if s.si.is_empty() || s.sj.is_empty() || near.iter().any(|&o| self.occluders.hides(o as usize, &s.si, &s.sj, eps)) {
                    s.near = near;
                    s.cands = cands;
                    return 0.0;
                }
            }
            let all = std::mem::replace(cands.as_mut().unwrap(), near);
            s.near = all;
        }
        if cands.as_ref().is_none_or(|c| !c.is_empty()) {
            shaft_planes(pi, pj, eps, &mut s.shaft);
            // The pair's own planes too, strictly behind `eps` (the polygon test below keeps
            // what reaches `eps` exactly, and rejects nothing more with them): whole subtrees
            // behind either polygon or outside the shaft are skipped — in a city the pair's
            // box holds thousands of facets, its shaft a few.
            s.shaft.push((ni, ni.dot(oi) - 1e-3 * eps));
            s.shaft.push((nj, nj.dot(oj) - 1e-3 * eps));
        }
        let occ = &mut s.occ;
        let shaft = &s.shaft;
        let (a, b) = (&mut s.eval.a, &mut s.eval.b);
        let flat = &self.occluders.flat;
        let (flat_i, flat_j) = (ctx.flatness[patch_i as usize], ctx.flatness[patch_j as usize]);
        let mut visit = |k: u32| {
            if k == own_i || k == own_j {
                return;
            }
            let v = &occluders[k as usize];
            // A polygon in the sender's or the receiver's plane (within the planarity
            // tolerance inputs are accepted with) blocks nothing in front of it. With `eps`
            // alone, the back copy of a slightly warped quad, which lies up to that
            // tolerance in front of its front copy, hid almost everything from it: office2's
            // chair legs in the furnace room gathered 0.4 % of their row (issue 9).
            let tol = flat[k as usize].max(flat_i).max(flat_j);
            if v.iter().all(|p| ni.dot(*p - oi).abs() <= tol) || v.iter().all(|p| nj.dot(*p - oj).abs() <= tol) {
                return;
            }
            clip_halfspace(v, |p| ni.dot(p - oi) - eps, 0.0, a);
            if a.is_empty() {
                return;
            }
            clip_halfspace(a, |p| nj.dot(p - oj) - eps, 0.0, b);
            if b.is_empty() {
                return;
            }
            // Outside (or on) a face of the pair's convex hull: cannot meet a segment
            // between the two polygons' interiors.
            if shaft.iter().any(|(n, d)| b.iter().all(|p| n.dot(*p) - d <= eps)) {
                return;
            }
            occ.push(k);
        };
        match &mut cands {
            Some(c) => {
                for &k in c.iter() {
                    visit(k);
                }
                // Give the face pair's list back.
                std::mem::swap(c, &mut s.near);
            }
            None => self.tree.query_pruned(lo, hi, shaft, eps, &mut visit),
        }
        s.cands = cands;
        // The receiver's overlaps with lower-numbered twins belong to them and are cut out
        // of it, except for the row's own element, which gathers over all of its area.
        let cuts: &[u32] = if s.twin_sender.is_none() { &self.twins[patch_j as usize] } else { &[] };
        if s.occ.is_empty() && !ctx.opts.adaptive_always_integrate && s.cover_sender.is_none() && s.twin_sender.is_none() && cuts.is_empty() {
            return analytic::area_factor_with(&mut s.an, pi, ni, pj, nj);
        }
        // Only the part of each polygon in front of the other can exchange energy; cutting
        // the rest off removes the integrand's jump where the sender crosses the
        // receiver's plane.
        let (mut si, mut sj) = (Vec::new(), Vec::new());
        clip_halfspace(pi, |p| nj.dot(p - oj), eps, &mut si);
        clip_halfspace(pj, |p| ni.dot(p - oi), eps, &mut sj);
        if si.is_empty() || sj.is_empty() {
            return 0.0;
        }
        // Hidden behind one occluder: nothing to integrate (most pairs in a city, whose
        // buildings stand between them).
        if s.occ.iter().any(|&o| self.occluders.hides(o as usize, &si, &sj, eps)) {
            return 0.0;
        }
        let cut_polys: Vec<&[DVec3]> = cuts.iter().filter(|&&t| t != patch_i).map(|&t| polys[t as usize].vertices.as_slice()).collect();
        let recv = Receiver::new(&sj, nj, &cut_polys, &mut s.eval);
        if recv.pieces.is_empty() {
            return 0.0;
        }
        // Start from regions no larger than about half the distance between the two
        // polygons, so that no shadow feature is narrower than the first samples' spacing.
        // (Each piece of the sender is held to this by its own size, see [`start_level`].)
        let min_level = if s.occ.is_empty() { 0 } else { start_level(&si, recv.centroid) };
        // A partly covered sender is integrated over its open cells (merged into convex
        // rectangles of its parameter domain), so that the integral and the open area it
        // is divided by are one region.
        let parts: Vec<Vec<DVec3>> = match s.cover_sender {
            Some(e) => ctx
                .receivers
                .open_pieces(ctx.mesh, e as usize)
                .into_iter()
                .filter_map(|r| {
                    let mut c = Vec::new();
                    clip_halfspace(&r, |p| nj.dot(p - oj), eps, &mut c);
                    (c.len() >= 3).then_some(c)
                })
                .collect(),
            None => vec![si],
        };
        let twin_eps = 100.0 * ctx.eps; // 1e-7 of the scene diagonal
        let mut pieces = Vec::new();
        for part in &parts {
            for piece in self.sender_pieces(part, ni, &recv, s) {
                if let Some(t) = s.twin_sender {
                    // The overlap with a lower-numbered twin sends as that twin.
                    let c = piece.iter().copied().sum::<DVec3>() / piece.len() as f64;
                    if self.twins[t as usize].iter().any(|&o| super::geom::inside_convex(c, &polys[o as usize].vertices, polys[o as usize].normal, twin_eps)) {
                        continue;
                    }
                }
                pieces.push(piece);
            }
        }
        self.integrate(&pieces, ni, &recv, min_level, s)
    }

    /// The occluders that can come between any part of occluder `p` and any part of
    /// occluder `q` (the polygons of the two faces being pairs' senders and receivers):
    /// those meeting the convex hull of the two, in front of both, with a margin of
    /// `eps` so that every element pair's own search ([`Self::pair_directed`]) finds
    /// its occluders among them. `None` when one of them hides all of `q` from all of
    /// `p` ([`Occluders::hides`]), so every pair between them is 0.
    fn between(&self, p: u32, q: u32, s: &mut Scratch) -> Option<Vec<u32>> {
        let eps = self.ctx.eps;
        let occ = &self.occluders;
        let (vp, vq) = (&occ.verts[p as usize], &occ.verts[q as usize]);
        let (np, nq) = (occ.normal[p as usize], occ.normal[q as usize]);
        let (op, oq) = (vp[0], vq[0]);
        // An element's plane is the face's to `eps` where the face is flat, else to the
        // planarity tolerance.
        let margin = |k: u32| if occ.planar[k as usize] { 2.0 * eps } else { 2.0 * eps + occ.flat[k as usize] };
        let (mp, mq) = (margin(p), margin(q));
        let (lo1, hi1) = occ.bounds[p as usize];
        let (lo2, hi2) = occ.bounds[q as usize];
        let (lo, hi) = (lo1.min(lo2) - DVec3::splat(eps), hi1.max(hi2) + DVec3::splat(eps));
        // Elements lie in the convex hull of their face (bilinear elements of a warped
        // quad too), so the hull of the two faces holds every pair's.
        let mut shaft = Vec::new();
        shaft_planes(vp, vq, eps, &mut shaft);
        shaft.push((np, np.dot(op) - mp));
        shaft.push((nq, nq.dot(oq) - mq));
        let mut out = Vec::new();
        let (a, b) = (&mut s.eval.a, &mut s.eval.b);
        self.tree.query_pruned(lo, hi, &shaft, -eps, &mut |k| {
            if k == p || k == q {
                return;
            }
            clip_halfspace(&occ.verts[k as usize], |x| np.dot(x - op) + mp, 0.0, a);
            clip_halfspace(a, |x| nq.dot(x - oq) + mq, 0.0, b);
            if b.is_empty() || shaft.iter().any(|(n, d)| b.iter().all(|x| n.dot(*x) - d <= -eps)) {
                return;
            }
            out.push(k);
        });
        if occ.planar[p as usize] && occ.planar[q as usize] {
            let (mut sp, mut sq) = (Vec::new(), Vec::new());
            clip_halfspace(vp, |x| nq.dot(x - oq), eps, &mut sp);
            clip_halfspace(vq, |x| np.dot(x - op), eps, &mut sq);
            if !sp.is_empty() && !sq.is_empty() && out.iter().any(|&o| occ.hides(o as usize, &sp, &sq, eps)) {
                return None;
            }
        }
        Some(out)
    }

    /// The sender cut into convex pieces along every line where an occluder meets its
    /// plane: a box standing on the floor hides everything from the floor under it and
    /// nothing just beside it, a jump that cubature cannot resolve but a cut removes.
    fn sender_pieces(&self, si: &[DVec3], ni: DVec3, recv: &Receiver, s: &mut Scratch) -> Vec<Vec<DVec3>> {
        let eps = self.ctx.eps;
        let frame = PlaneFrame::new(si[0], ni);
        let mut outline: Vec<DVec2> = si.iter().map(|p| frame.to_2d(*p)).collect();
        if area2_2d(&outline) < 0.0 {
            outline.reverse();
        }
        let area = 0.5 * area2_2d(&outline);
        let mut set = PieceSet::default();
        set.push(&outline);
        let mut next = PieceSet::default();
        for &o in s.occ.iter() {
            // Points of the occluder's boundary on the sender's plane.
            let v = &self.occluders.verts[o as usize];
            let d: Vec<f64> = v.iter().map(|p| ni.dot(*p - si[0])).collect();
            let mut on: Vec<DVec3> = Vec::new();
            for k in 0..v.len() {
                let (a, b) = (v[k], v[(k + 1) % v.len()]);
                let (da, db) = (d[k], d[(k + 1) % v.len()]);
                if da.abs() <= eps {
                    on.push(a);
                }
                if (da > eps && db < -eps) || (da < -eps && db > eps) {
                    on.push(a + (b - a) * (da / (da - db)));
                }
            }
            if on.len() < 2 {
                continue;
            }
            // The segment's line (its two farthest points).
            let (mut pa, mut pb, mut best) = (on[0], on[1], 0.0);
            for x in &on {
                for y in &on {
                    let l = (*x - *y).length_squared();
                    if l > best {
                        best = l;
                        pa = *x;
                        pb = *y;
                    }
                }
            }
            if best.sqrt() <= eps {
                continue;
            }
            set.split(frame.to_2d(pa), frame.to_2d(pb), 1e-12 * area.sqrt(), 1e-12 * area, &mut next);
            std::mem::swap(&mut set, &mut next);
        }
        // The sender is cut along the shadow events only where that leaves at most
        // [`MAX_EVENT_PIECES`] pieces. A one-metre facet of a city sees a few events (a
        // building's edges), and the cuts make its integral 8 times cheaper; a whole wall
        // of the Cornell box behind two boxes is crossed by hundreds, and the cuts would
        // leave hundreds of pieces, many touching the receiver's plane, each with its own
        // cubature and exact integrals (the box 0.4 s → 300 s). The cuts only partition
        // the sender, so leaving them out changes nothing but the cost.
        let mut cut = set.clone();
        let mut many = false;
        self.event_cuts(&outline, &frame, recv, s, &mut |a, b| {
            if !many {
                cut.split(a, b, 1e-12 * area.sqrt(), 1e-12 * area, &mut next);
                std::mem::swap(&mut cut, &mut next);
                many = cut.len() > MAX_EVENT_PIECES;
            }
        });
        if !many {
            set = cut;
        }
        (0..set.len()).map(|k| set.piece(k).iter().map(|q| frame.to_3d(*q)).collect()).collect()
    }

    /// Lines of the sender's plane across which the visible part of the receiver changes
    /// shape (the EV and VE events of discontinuity meshing: Heckbert 1992; Lischinski,
    /// Tampieri & Greenberg 1992), for each occluder alone: where the shadow of an
    /// occluder edge passes over a receiver vertex, and where the shadow of an occluder
    /// vertex crosses a receiver edge. Both are segments between the points `P(v, a)`,
    /// occluder vertex `a` seen from receiver vertex `v` on the sender's plane: `P(v,a)`–
    /// `P(v,b)` for an occluder edge `ab`, `P(v,a)`–`P(w,a)` for a receiver edge `vw`.
    /// Between them the integrand is smooth, so cutting the sender along every segment
    /// that crosses it lets the cubature converge in a few rules instead of chasing the
    /// kinks. The cuts only partition the sender (any subset gives the same integral), so
    /// events that are not bounded segments, and those between two occluders, are left
    /// to the adaptive refinement.
    fn event_cuts(&self, outline: &[DVec2], frame: &PlaneFrame, recv: &Receiver, s: &mut Scratch, cut: &mut dyn FnMut(DVec2, DVec2)) {
        let eps = self.ctx.eps;
        let (ns, os) = (frame.n, frame.origin);
        let (nr, or) = (recv.normal, recv.verts[0]);
        let rv = recv.verts;
        let m = rv.len();
        let (lo, hi) = bounds_2d(outline);
        let ext = (hi - lo).length();
        // Does the segment a–b cross the (counter-clockwise, convex) outline's interior?
        let crosses = |a: DVec2, b: DVec2| -> bool {
            let (mut t0, mut t1) = (0.0f64, 1.0f64);
            let d = b - a;
            for k in 0..outline.len() {
                let (p, q) = (outline[k], outline[(k + 1) % outline.len()]);
                let e = q - p;
                // Inside: left of the edge.
                let fa = e.perp_dot(a - p);
                let fd = e.perp_dot(d);
                if fd.abs() < 1e-300 {
                    if fa <= 0.0 {
                        return false;
                    }
                    continue;
                }
                let t = -fa / fd;
                if fd > 0.0 {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
                if t1 - t0 <= 1e-9 {
                    return false;
                }
            }
            (t1 - t0) * d.length() > 1e-9 * ext
        };
        let mut proj: Vec<Option<DVec2>> = Vec::new();
        for &o in s.occ.iter() {
            let v = &self.occluders.verts[o as usize];
            clip_halfspace(v, |p| ns.dot(p - os) - eps, 0.0, &mut s.eval.a);
            clip_halfspace(&s.eval.a, |p| nr.dot(p - or) - eps, 0.0, &mut s.eval.b);
            let occ = &s.eval.b;
            let k = occ.len();
            if k < 2 {
                continue;
            }
            // P(v, a): the ray from receiver vertex v through a, met on the sender plane.
            proj.clear();
            for &r in rv {
                for &a in occ {
                    let d = a - r;
                    let den = ns.dot(d);
                    let t = ns.dot(os - r) / den;
                    proj.push((den.abs() > 1e-300 && t > 0.0 && t.is_finite()).then(|| frame.to_2d(r + d * t)));
                }
            }
            let at = |vi: usize, ai: usize| proj[vi * k + ai];
            // A segment where both ends reach the plane; where one does not, the event
            // runs on to infinity along the line where the event's plane (normal `m`)
            // meets the sender's plane: cut along all of that line.
            let mut event = |p: Option<DVec2>, q: Option<DVec2>, m: DVec3| match (p, q) {
                (Some(p), Some(q)) => {
                    if crosses(p, q) {
                        cut(p, q);
                    }
                }
                (Some(p), None) | (None, Some(p)) => {
                    let d3 = m.cross(ns);
                    let d = DVec2::new(d3.dot(frame.e1), d3.dot(frame.e2));
                    let len = d.length();
                    if len > 1e-300 {
                        let d = d * (ext / len);
                        let side = |x: DVec2| d.perp_dot(x - p);
                        let (mut pos, mut neg) = (false, false);
                        for &x in outline {
                            let sd = side(x);
                            pos |= sd > 1e-9 * ext * ext;
                            neg |= sd < -1e-9 * ext * ext;
                        }
                        if pos && neg {
                            cut(p, p + d);
                        }
                    }
                }
                (None, None) => {}
            };
            for vi in 0..m {
                let r = rv[vi];
                for ai in 0..k {
                    let (a, b) = (occ[ai], occ[(ai + 1) % k]);
                    // EV: occluder edge (a, b) from receiver vertex v.
                    event(at(vi, ai), at(vi, (ai + 1) % k), (a - r).cross(b - r));
                    // VE: occluder vertex a over receiver edge (v, w).
                    let w = rv[(vi + 1) % m];
                    event(at(vi, ai), at((vi + 1) % m, ai), (r - a).cross(w - a));
                }
            }
        }
    }

    /// Adaptive cubature of `F(dA_x → V_j(x))` over the sender's convex pieces, one error
    /// budget and one evaluation budget for them all. Each region keeps the occluders that
    /// can still reach the shaft between it and the receiver; a region left with none is
    /// integrated exactly (contour integral, error 0), so only regions in penumbra are ever
    /// refined, and each evaluation there clips only its own occluders.
    fn integrate(&self, pieces: &[Vec<DVec3>], ni: DVec3, recv: &Receiver, min_level: u32, s: &mut Scratch) -> f64 {
        let opts = self.ctx.opts;
        let area_i: f64 = pieces.iter().map(|p| super::geom::area_3d(p)).sum();
        let Scratch { occ, eval, heap, an, rshaft, .. } = &mut *s;
        heap.clear();
        let mut evals = 0usize;
        let mut total = 0.0;
        let mut err = 0.0;
        let mut ctx = RegionCtx { rows: self, ni, recv, eval, an, shaft: rshaft };
        for pi in pieces {
            for k in 1..pi.len() - 1 {
                let tri = [pi[0], pi[k], pi[k + 1]];
                let mut todo = vec![tri];
                // A piece cut out of the sender along shadow events starts from its own
                // size, never finer than the whole sender would.
                let level = if pieces.len() > 1 { min_level.min(start_level(pi, recv.centroid)) } else { min_level };
                for _ in 0..level {
                    todo = todo.iter().flat_map(split4).collect();
                }
                for t in todo {
                    let r = ctx.eval(t, occ, &mut evals);
                    total += r.est;
                    err += r.err;
                    heap.push(r);
                }
            }
        }
        let tol = opts.adaptive_tolerance;
        loop {
            let target = (tol * total.abs()).max(tol * 1e-3 * area_i);
            if err <= target || evals + 4 * EVALS_PER_REGION > opts.adaptive_max_evaluations {
                // Recompute the sums exactly before deciding (running sums drift).
                let (t, e) = heap.iter().fold((0.0, 0.0), |(t, e), r| (t + r.est, e + r.err));
                total = t;
                err = e;
                let target = (tol * total.abs()).max(tol * 1e-3 * area_i);
                if err <= target {
                    break;
                }
                if evals + 4 * EVALS_PER_REGION > opts.adaptive_max_evaluations {
                    self.budget.record(total, err);
                    break;
                }
            }
            let Some(worst) = heap.pop() else { break };
            if worst.err == 0.0 {
                heap.push(worst);
                break;
            }
            total -= worst.est;
            err -= worst.err;
            for t in split4(&worst.tri) {
                let r = ctx.eval(t, &worst.occ, &mut evals);
                total += r.est;
                err += r.err;
                heap.push(r);
            }
        }
        s.evals += evals;
        total
    }

    /// Pyramid side planes through `x` and each receiver edge, oriented inwards.
    fn pyramid(x: DVec3, recv: &Receiver, sides: &mut Vec<DVec3>) {
        sides.clear();
        let m = recv.verts.len();
        for k in 0..m {
            let (a, b) = (recv.verts[k], recv.verts[(k + 1) % m]);
            let mut pn = (a - x).cross(b - x);
            if pn.dot(recv.centroid - x) < 0.0 {
                pn = -pn;
            }
            sides.push(pn);
        }
    }

    /// The shadow of occluder `o` from `x` (at height `dx` above the receiver's plane) on
    /// the receiver's plane, counter-clockwise in `s.shadow`; false if it has no area.
    ///
    /// With `always_clip`, it is clipped to the pyramid over the receiver
    /// ([`Self::pyramid`], in `s.sides`). Otherwise the pyramid is used only where it is
    /// needed: an occluder that lies well below `x` (every point under 0.999 `dx`) projects
    /// to a convex polygon of bounded size, and cutting the receiver's pieces by all of it
    /// cuts them by its part inside the pyramid. (Points at or above `x`'s height never
    /// block: a segment from `x` down to the receiver stays below it; an occluder that
    /// reaches close to that height takes the pyramid, whose clip keeps its shadow finite.)
    fn shadow(&self, x: DVec3, dx: f64, o: u32, recv: &Receiver, always_clip: bool, s: &mut EvalScratch) -> bool {
        let fr = &recv.frame;
        let height = |q: &DVec3| fr.n.dot(*q - fr.origin);
        clip_halfspace(&self.occluders.verts[o as usize], |p| height(&p), 0.0, &mut s.a);
        if always_clip || s.a.iter().any(|q| height(q) > 0.999 * dx) {
            for pn in &s.sides {
                if s.a.is_empty() {
                    break;
                }
                clip_halfspace(&s.a, |p| pn.dot(p - x), 0.0, &mut s.b);
                std::mem::swap(&mut s.a, &mut s.b);
            }
        }
        // Central projection from x onto the receiver plane.
        s.shadow.clear();
        for q in &s.a {
            let den = dx - height(q);
            if den > 0.0 {
                s.shadow.push(fr.to_2d(x + (*q - x) * (dx / den)));
            }
        }
        if s.shadow.len() < 3 {
            return false;
        }
        let a2 = area2_2d(&s.shadow);
        if a2.abs() <= 2.0 * recv.min_area {
            return false;
        }
        if a2 < 0.0 {
            s.shadow.reverse();
        }
        true
    }

    /// `F(dA_x → V_j(x))`: the exact factor from the point to the receiver's visible part.
    fn visible_factor(&self, x: DVec3, nx: DVec3, recv: &Receiver, occ: &[u32], s: &mut EvalScratch) -> f64 {
        let fr = &recv.frame;
        let dx = fr.n.dot(x - fr.origin);
        if dx <= 0.0 {
            return 0.0;
        }
        if occ.is_empty() {
            return recv.pieces.iter().map(|p| point_to_polygon_unsided(x, nx, p)).sum();
        }
        Self::pyramid(x, recv, &mut s.sides);
        s.pieces.clear();
        for k in 0..recv.start.len() {
            s.pieces.push(recv.start.piece(k));
        }
        let (mut plo, mut phi) = s.pieces.bounds();
        for &o in occ {
            if !self.shadow(x, dx, o, recv, false, s) {
                continue;
            }
            let (lo, hi) = bounds_2d(&s.shadow);
            if lo.x >= phi.x || lo.y >= phi.y || hi.x <= plo.x || hi.y <= plo.y {
                continue;
            }
            s.pieces.subtract(&s.shadow, recv.eps2, recv.min_area, &mut s.next, &mut s.tmp2);
            std::mem::swap(&mut s.pieces, &mut s.next);
            if s.pieces.is_empty() {
                return 0.0;
            }
            (plo, phi) = s.pieces.bounds();
        }
        let mut f = 0.0;
        for k in 0..s.pieces.len() {
            s.lift.clear();
            s.lift.extend(s.pieces.piece(k).iter().map(|q| fr.to_3d(*q)));
            f += point_to_polygon_unsided(x, nx, &s.lift);
        }
        // Never negative but for round-off (a piece within `eps` of the sender's plane).
        f.max(0.0)
    }
}

/// Planes `n·p = d` of the convex hull of two polygons that pass through an edge of one
/// and a vertex of the other (the "shaft" of Haines & Wallace 1994), each oriented with
/// the hull on its positive side. Together with the polygons' own planes they bound the
/// hull, so a polygon entirely on the negative side of one of them cannot block.
fn shaft_planes(pi: &[DVec3], pj: &[DVec3], eps: f64, out: &mut Vec<(DVec3, f64)>) {
    out.clear();
    for (a, b) in [(pi, pj), (pj, pi)] {
        for k in 0..a.len() {
            let (e0, e1) = (a[k], a[(k + 1) % a.len()]);
            for &v in b {
                // Unnormalised until it is kept: the side test scales `eps` instead.
                let n = (e1 - e0).cross(v - e0);
                let len2 = n.length_squared();
                if !(len2 > 0.0) {
                    continue;
                }
                let len = len2.sqrt();
                let (d, tol) = (n.dot(e0), eps * len);
                let (mut pos, mut neg) = (false, false);
                for p in a.iter().chain(b) {
                    let s = n.dot(*p) - d;
                    pos |= s > tol;
                    neg |= s < -tol;
                    if pos && neg {
                        break;
                    }
                }
                match (pos, neg) {
                    (true, false) => out.push((n / len, d / len)),
                    (false, true) => out.push((-n / len, -d / len)),
                    _ => {}
                }
            }
        }
    }
}

const EVALS_PER_REGION: usize = 9 + 16;

/// The most pieces the shadow events may cut a sender into ([`Rows::sender_pieces`]).
const MAX_EVENT_PIECES: usize = 16;

/// A sender triangle with its estimate of `∫ f`, the error of that estimate, and the
/// occluders that can reach the shaft between it and the receiver.
struct Region {
    tri: [DVec3; 3],
    est: f64,
    err: f64,
    occ: Vec<u32>,
}

/// What evaluating a region needs.
struct RegionCtx<'r, 'a> {
    rows: &'r Rows<'a>,
    ni: DVec3,
    recv: &'r Receiver<'r>,
    eval: &'r mut EvalScratch,
    an: &'r mut analytic::Scratch,
    shaft: &'r mut Vec<(DVec3, f64)>,
}

impl RegionCtx<'_, '_> {
    fn eval(&mut self, tri: [DVec3; 3], parent_occ: &[u32], evals: &mut usize) -> Region {
        // The parent's occluders that still meet this region's shaft.
        let eps = self.rows.ctx.eps;
        shaft_planes(&tri, self.recv.verts, eps, self.shaft);
        let occluders = &self.rows.occluders.verts;
        let mut occ: Vec<u32> = parent_occ
            .iter()
            .copied()
            .filter(|&o| {
                let v = &occluders[o as usize];
                !self.shaft.iter().any(|(n, d)| v.iter().all(|p| n.dot(*p) - d <= eps))
            })
            .collect();
        // In umbra behind one occluder: exactly nothing.
        if occ.iter().any(|&o| self.rows.occluders.hides(o as usize, &tri, self.recv.verts, eps)) {
            return Region { tri, est: 0.0, err: 0.0, occ: Vec::new() };
        }
        self.order(&tri, &mut occ);
        if occ.is_empty() {
            // The integrand is never negative: a negative exact integral is round-off of the
            // contour terms (a sliver region nearly in the receiver's plane).
            let est = self.recv.pieces.iter().map(|p| analytic::area_factor_with(self.an, &tri, self.ni, p, self.recv.normal).max(0.0)).sum();
            return Region { tri, est, err: 0.0, occ };
        }
        *evals += EVALS_PER_REGION;
        let area2 = (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
        let mut rule = |n: usize| {
            let gl = gauss_legendre(n);
            let mut acc = 0.0;
            for &(x, wx) in gl {
                for &(y, wy) in gl {
                    let p = tri[0] + (tri[1] - tri[0]) * x + (tri[2] - tri[1]) * (x * y);
                    acc += wx * wy * x * self.rows.visible_factor(p, self.ni, self.recv, &occ, self.eval);
                }
            }
            acc * area2
        };
        let lo = rule(3);
        let hi = rule(4);
        Region { tri, est: hi, err: (hi - lo).abs(), occ }
    }
}

impl RegionCtx<'_, '_> {
    /// Sorts the occluders by the area of their shadow on the receiver seen from the
    /// region's centroid, largest first: the receiver is then used up by few large cuts
    /// (and a point that sees nothing stops early) instead of being cut into many small
    /// pieces first.
    fn order(&mut self, tri: &[DVec3; 3], occ: &mut [u32]) {
        if occ.len() < 2 {
            return;
        }
        let x = (tri[0] + tri[1] + tri[2]) / 3.0;
        let fr = &self.recv.frame;
        let dx = fr.n.dot(x - fr.origin);
        if dx <= 0.0 {
            return;
        }
        Rows::pyramid(x, self.recv, &mut self.eval.sides);
        // Shadows are counter-clockwise (area ≥ 0), whose f64 bits order as the areas do;
        // the sort is stable, so ties keep their order.
        occ.sort_by_cached_key(|&o| {
            let a = if self.rows.shadow(x, dx, o, self.recv, true, self.eval) { area2_2d(&self.eval.shadow) } else { 0.0 };
            std::cmp::Reverse(a.to_bits())
        });
    }
}

impl PartialEq for Region {
    fn eq(&self, o: &Self) -> bool {
        self.err == o.err
    }
}
impl Eq for Region {}
impl PartialOrd for Region {
    fn partial_cmp(&self, o: &Self) -> Option<CmpOrdering> {
        Some(self.cmp(o))
    }
}
impl Ord for Region {
    fn cmp(&self, o: &Self) -> CmpOrdering {
        self.err.total_cmp(&o.err)
    }
}

/// Subdivision levels (at most 4) that bring `poly`'s triangles to about half its
/// distance from `target` or less: no shadow feature is then narrower than the first
/// samples' spacing.
fn start_level(poly: &[DVec3], target: DVec3) -> u32 {
    let (lo, hi) = bounds_3d(poly);
    let diam = (hi - lo).length();
    let c = poly.iter().copied().sum::<DVec3>() / poly.len() as f64;
    let dist = (target - c).length().max(1e-300);
    ((2.0 * diam / dist).log2().ceil() as i32).clamp(0, 4) as u32
}

/// The four midpoint sub-triangles.
fn split4(t: &[DVec3; 3]) -> [[DVec3; 3]; 4] {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
    [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
}

/// A bounding-box hierarchy over the scene's polygons, for "which polygons meet this box".
pub(crate) struct PolyTree {
    nodes: Vec<TreeNode>,
    items: Vec<u32>,
}

#[derive(Clone, Copy)]
struct TreeNode {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first item; interior: left child (right = left + 1).
    start: u32,
    /// Leaf: item count (> 0); interior: 0.
    count: u32,
}

impl PolyTree {
    pub fn new(polys: &[Vec<DVec3>]) -> Self {
        let boxes: Vec<(DVec3, DVec3)> = polys.iter().map(|p| bounds_3d(p)).collect();
        let mut items: Vec<u32> = (0..polys.len() as u32).collect();
        let mut nodes = vec![TreeNode { lo: DVec3::ZERO, hi: DVec3::ZERO, start: 0, count: 0 }];
        if !items.is_empty() {
            Self::build(&boxes, &mut items, 0, 0, polys.len(), &mut nodes);
        }
        PolyTree { nodes, items }
    }

    fn build(boxes: &[(DVec3, DVec3)], items: &mut [u32], node: usize, start: usize, end: usize, nodes: &mut Vec<TreeNode>) {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let (mut clo, mut chi) = (lo, hi);
        for &k in &items[start..end] {
            let (a, b) = boxes[k as usize];
            lo = lo.min(a);
            hi = hi.max(b);
            let c = (a + b) * 0.5;
            clo = clo.min(c);
            chi = chi.max(c);
        }
        let n = end - start;
        if n <= 4 {
            nodes[node] = TreeNode { lo, hi, start: start as u32, count: n as u32 };
            return;
        }
        let ext = chi - clo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = start + n / 2;
        items[start..end].select_nth_unstable_by(n / 2, |&a, &b| {
            let ca = boxes[a as usize].0[axis] + boxes[a as usize].1[axis];
            let cb = boxes[b as usize].0[axis] + boxes[b as usize].1[axis];
            ca.total_cmp(&cb)
        });
        let left = nodes.len();
        nodes.push(TreeNode { lo, hi, start: 0, count: 0 });
        nodes.push(TreeNode { lo, hi, start: 0, count: 0 });
        nodes[node] = TreeNode { lo, hi, start: left as u32, count: 0 };
        Self::build(boxes, items, left, start, mid, nodes);
        Self::build(boxes, items, left + 1, mid, end, nodes);
    }

    /// Calls `f` with every polygon whose bounding box overlaps `[lo, hi]`, skipping nodes
    /// whose box lies entirely on the non-positive side (`n·p − d ≤ eps`) of one of
    /// `planes`.
    pub fn query_pruned(&self, lo: DVec3, hi: DVec3, planes: &[(DVec3, f64)], eps: f64, f: &mut dyn FnMut(u32)) {
        if self.items.is_empty() {
            return;
        }
        let mut stack = vec![0usize];
        while let Some(k) = stack.pop() {
            let n = self.nodes[k];
            if n.lo.cmpgt(hi).any() || n.hi.cmplt(lo).any() {
                continue;
            }
            // The box corner farthest along each plane's normal.
            if planes.iter().any(|(pn, d)| {
                let far = DVec3::select(pn.cmpgt(DVec3::ZERO), n.hi, n.lo);
                pn.dot(far) - d <= eps
            }) {
                continue;
            }
            if n.count > 0 {
                for &it in &self.items[n.start as usize..(n.start + n.count) as usize] {
                    f(it);
                }
            } else {
                stack.push(n.start as usize);
                stack.push(n.start as usize + 1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::SceneRays;
    use crate::mesh::Mesh;
    use crate::scene::{builtin, Scene};

    /// The integrand against brute force (receiver on a fine grid, visibility by rays) at a
    /// point of the Cornell box's back wall that sees short_1 only past the tall block.
    #[test]
    fn visible_factor_matches_ray_sampling_behind_an_occluder() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let rays = SceneRays::new(&scene.polygons);
        let mesh = Mesh::default();
        let opts = super::super::Options::default();
        let receivers = crate::mesh::Receivers::default();
        let ctx = Context::new(&scene, &mesh, &rays, &receivers, &opts);
        let rows = Rows::new(&ctx);
        let find = |name: &str| scene.polygons.iter().position(|p| scene.objects[p.object as usize].name == name).unwrap() as u32;
        let (pa, pb) = (find("back_wall"), find("short_1"));
        let (sa, sb) = (&scene.polygons[pa as usize], &scene.polygons[pb as usize]);
        let mut s = rows.scratch();
        let _ = rows.pair_directed(&sa.vertices, sa.normal, pa, &sb.vertices, sb.normal, pb, &mut s);
        assert!(!s.occ.is_empty());
        let recv = Receiver::new(&sb.vertices, sb.normal, &[], &mut s.eval);
        let x = DVec3::new(353.3, 98.0, 559.2);
        let occ = s.occ.clone();
        let exact = rows.visible_factor(x, sa.normal, &recv, &occ, &mut s.eval);
        // Brute force: 1200² midpoints over short_1's fan triangles.
        // (A straight shadow edge on a regular grid makes the brute force oscillate by
        // about ±0.5 % as k grows: it bounds the exact value, no more. The closure tests in
        // tests/view_factors.rs check the integrated factors to 1e-6.)
        let v = &sb.vertices;
        let k = 1200;
        let mut brute = 0.0;
        for t in 1..v.len() - 1 {
            let (a, b, c) = (v[0], v[t], v[t + 1]);
            let area = 0.5 * (b - a).cross(c - a).length();
            for i in 0..k {
                for j in 0..k {
                    let (u, w) = ((i as f64 + 0.5) / k as f64, (j as f64 + 0.5) / k as f64);
                    let y = a + (b - a) * u + (c - b) * (u * w);
                    let d = y - x;
                    let r2 = d.length_squared();
                    let (ci, cj) = (sa.normal.dot(d) / r2.sqrt(), -sb.normal.dot(d) / r2.sqrt());
                    if ci > 0.0 && cj > 0.0 && rays.visible(x, pa, y, pb) {
                        brute += ci * cj / (std::f64::consts::PI * r2) * 2.0 * area * u / (k * k) as f64;
                    }
                }
            }
        }
        let unoccluded = point_to_polygon_unsided(x, sa.normal, &sb.vertices);
        assert!(exact < 0.1 * unoccluded, "mostly hidden: {exact} vs {unoccluded}");
        assert!((exact - brute).abs() < 1e-2 * exact, "{exact} vs {brute}");
    }

    #[test]
    fn shaft_planes_bound_the_hull() {
        let a = [DVec3::new(0., 0., 0.), DVec3::new(1., 0., 0.), DVec3::new(1., 1., 0.), DVec3::new(0., 1., 0.)];
        let b = [DVec3::new(0., 0., 1.), DVec3::new(0., 1., 1.), DVec3::new(1., 1., 1.), DVec3::new(1., 0., 1.)];
        let mut planes = Vec::new();
        shaft_planes(&a, &b, 1e-12, &mut planes);
        // The unit cube's four side planes (each found several times).
        let inside = DVec3::splat(0.5);
        assert!(planes.iter().all(|(n, d)| n.dot(inside) - d > 0.0));
        let outside = DVec3::new(1.5, 0.5, 0.5);
        assert!(planes.iter().any(|(n, d)| n.dot(outside) - d < 0.0));
    }
}
