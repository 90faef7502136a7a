//! Coverage: which parts of each element lie inside closed geometry.
//!
//! Real scenes put objects on floors and against walls without cutting the floor polygon
//! along the contact (the Cornell boxes stand on the floor; RenderPark furniture touches
//! walls). A constant element that straddles such a contact averages the lit part with the
//! dark part underneath, and every other surface then sees it too dark — a first-order
//! error that mesh refinement only halves per level. Instead, each element carries a fixed
//! set of receiver points (`k × k` midpoints of a regular grid in its parameter domain,
//! k = 1, 2, 3) and a point is *covered* when every one of [`PROBES`] probe rays leaving it
//! (cosine-distributed about the normal) hits the back side of a surface first, i.e. the
//! point lies inside a closed solid (for two-sided surfaces, "back" is the side opposite
//! the input winding's front; where a probe meets the back copy of a lone emitter, one
//! with an edge no other polygon shares, the point is covered only if the copy is covered
//! there too, tested at the first such hit: a lamp's emitting back is a surface, not the
//! inside of a solid; where light reaches a two-sided polygon only from behind, as on
//! every wall of a room wound outward, its sides swap roles, and where it reaches both
//! sides, as on a trough open at the bottom, neither is inside: [`super::lit_sides`]). Form
//! factors are gathered at open points only, so the
//! element's value is the radiosity of its open part; per-object averages weight each
//! element by its open fraction (covered area counts as zero, as in the path-traced
//! references), and the power formulation uses open areas.
//!
//! This is a cheap stand-in for discontinuity meshing along D0 discontinuities
//! (Lischinski, Tampieri & Greenberg 1992).

use glam::DVec3;
use rayon::prelude::*;

use super::lit_sides::Side;
use super::Mesh;
use crate::accel::SceneRays;
use crate::sampling::{basis, cosine_hemisphere, halton2};
use crate::scene::{newell_normal, Scene};

/// Probe rays per receiver point.
pub const PROBES: u32 = 8;

/// Largest receiver grid (k × k points).
pub const MAX_K: usize = 3;

/// Elements with `√area` below this fraction of the scene's diagonal are not probed on the
/// fine grid (their open cells follow the 3 × 3 points).
pub const FINE_SIZE: f64 = 1.0 / 200.0;

/// Grid used to measure the open fraction of elements that a contact edge crosses.
pub const FINE_K: usize = 8;
const _: () = assert!(FINE_K * FINE_K == 64, "open cells are one u64 per element");

/// Fixed receiver points of every element and which of them are open.
#[derive(Clone, Debug, Default)]
pub struct Receivers {
    /// Per element, for k = 1..=MAX_K: the open points of the k × k grid (k = 1: the open
    /// point nearest to the centroid of the open 3×3 points).
    points: Vec<[Vec<DVec3>; MAX_K]>,
    /// Per element, the open fraction of its area (estimated on the 3 × 3 grid, or on the
    /// [`FINE_K`] × [`FINE_K`] grid where a contact edge crosses the element).
    pub open_fraction: Vec<f64>,
    /// Per element, which cells of the [`FINE_K`] × [`FINE_K`] grid of its parameter
    /// domain are open (bit `j·FINE_K + i` for the cell `i` along u, `j` along v): the
    /// fine grid's result where it was probed, else all cells or none.
    pub open_cells: Vec<u64>,
    /// Probe rays cast.
    pub rays: u64,
    /// Per polygon: what a probe meets on each side of a two-sided pair, as light showed it
    /// ([`super::lit_sides`]); empty: the input winding throughout.
    pub sides: Vec<Side>,
}

impl Receivers {
    /// Open receiver points of element `e` on the `k × k` grid (1 ≤ k ≤ MAX_K); for an
    /// element that is entirely covered, all of them (it gathers, but has no open area).
    #[inline]
    pub fn points(&self, e: usize, k: usize) -> &[DVec3] {
        &self.points[e][k.clamp(1, MAX_K) - 1]
    }

    /// Effective (open) area of every element.
    pub fn open_areas(&self, mesh: &Mesh) -> Vec<f64> {
        mesh.elements.iter().zip(&self.open_fraction).map(|(e, f)| e.area * f).collect()
    }

    /// Receivers with no coverage test (every point open).
    pub fn all_open(mesh: &Mesh) -> Receivers {
        let points = mesh
            .elements
            .iter()
            .map(|e| {
                let mut lv: [Vec<DVec3>; MAX_K] = Default::default();
                for (k, l) in lv.iter_mut().enumerate() {
                    *l = grid(e, &mesh.positions, k + 1);
                }
                lv[0] = vec![e.centroid];
                lv
            })
            .collect();
        Receivers { points, open_fraction: vec![1.0; mesh.len()], open_cells: vec![u64::MAX; mesh.len()], rays: 0, sides: Vec::new() }
    }

    /// True if the point of element `e` at (u, v) lies in an open cell.
    #[inline]
    pub fn open_at(&self, e: usize, u: f64, v: f64) -> bool {
        let m = self.open_cells[e];
        m == u64::MAX || m & (1u64 << cell(u, v)) != 0
    }

    /// The open part of element `e` as convex polygons (counter-clockwise about its
    /// normal): runs of open cells along u, merged over rows with the same run into
    /// rectangles of the parameter domain. Lines of constant u or v are straight on both
    /// element shapes (bilinear quads; triangles, where v runs along rays from the first
    /// corner), so the polygons are exact and their areas sum to the open area.
    pub fn open_pieces(&self, mesh: &Mesh, e: usize) -> Vec<Vec<DVec3>> {
        open_polygons(&mesh.elements[e], &mesh.positions, self.open_cells[e])
    }

    /// The open cell of element `e` numbered `k` among its open cells (0 ≤ k < the number
    /// of open cells) as the (u, v) of its lower corner; None if no cell is open.
    pub fn open_cell(&self, e: usize, k: u32) -> Option<(f64, f64)> {
        let mut m = self.open_cells[e];
        if m == 0 {
            return None;
        }
        for _ in 0..k.min(m.count_ones() - 1) {
            m &= m - 1;
        }
        let b = m.trailing_zeros() as usize;
        Some(((b % FINE_K) as f64 / FINE_K as f64, (b / FINE_K) as f64 / FINE_K as f64))
    }

    /// The unit-square point `(u, v)` moved into element `e`'s open part: into its open cell
    /// numbered `pick() × (open cells)` (the cells are equal, so uniform `u`, `v` and `pick`
    /// give points uniform over the open part); unchanged when the element is all open or
    /// all covered (`pick` is then not called).
    #[inline]
    pub fn open_uv(&self, e: usize, u: f64, v: f64, pick: impl FnOnce() -> f64) -> (f64, f64) {
        let cells = self.open_cells[e];
        if cells == u64::MAX {
            return (u, v);
        }
        let k = (pick() * cells.count_ones() as f64) as u32;
        match self.open_cell(e, k) {
            Some((u0, v0)) => (u0 + u / FINE_K as f64, v0 + v / FINE_K as f64),
            None => (u, v),
        }
    }

    /// Receivers with the coverage test.
    pub fn compute(scene: &Scene, mesh: &Mesh, rays: &SceneRays) -> Receivers {
        Self::compute_with(scene, mesh, rays, &crate::NoProgress)
    }

    /// [`Receivers::compute`] reporting progress (stage "coverage"; the elements left are
    /// skipped once `progress` asks to stop, and the caller is expected to check it).
    pub fn compute_with(scene: &Scene, mesh: &Mesh, rays: &SceneRays, progress: &dyn crate::Progress) -> Receivers {
        Self::compute_given(scene, mesh, rays, Self::sides(scene, rays), progress)
    }

    /// What a probe meets on each side of the scene's two-sided pairs, as light shows it
    /// ([`super::lit_sides::sides`], started at points that the input winding's coverage test
    /// finds open): [`Receivers::sides`], for [`Receivers::compute_given`].
    pub fn sides(scene: &Scene, rays: &SceneRays) -> Vec<Side> {
        let diag = scene.diagonal().max(f64::MIN_POSITIVE);
        let probe = Probe { scene, rays, diag, lone_emitter: lone_emitters(scene), sides: Vec::new() };
        super::lit_sides::sides(scene, rays, &|p, n, q| !covered(p, n, q, &probe, &mut 0))
    }

    /// [`Receivers::compute_with`] with the `sides` of [`Receivers::sides`] already found.
    pub fn compute_given(scene: &Scene, mesh: &Mesh, rays: &SceneRays, sides: Vec<Side>, progress: &dyn crate::Progress) -> Receivers {
        let diag = scene.diagonal().max(f64::MIN_POSITIVE);
        let probe = Probe { scene, rays, diag, lone_emitter: lone_emitters(scene), sides };
        progress.begin("coverage", mesh.len() as u64);
        let done = std::sync::atomic::AtomicU64::new(0);
        let res: Vec<([Vec<DVec3>; MAX_K], f64, u64, u64)> = mesh
            .elements
            .par_iter()
            .with_min_len(16)
            .map(|e| {
                if done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) % 1024 == 1023 {
                    progress.advance(1024);
                }
                if progress.should_stop() {
                    return (Default::default(), 1.0, u64::MAX, 0);
                }
                let mut lv: [Vec<DVec3>; MAX_K] = Default::default();
                let mut cast = 0u64;
                // The 3 × 3 grid first: its centre is the k = 1 point, and where all nine
                // agree (and, when open, the corners too) the 2 × 2 points take their
                // verdict without probes of their own (an element that no contact edge
                // crosses is wholly open or wholly covered).
                let g3 = grid(e, &mesh.positions, MAX_K);
                let open: Vec<bool> =
                    g3.iter().map(|&p| !covered(p, e.normal, e.patch, &probe, &mut cast)).collect();
                let n3 = g3.len();
                let open3 = open.iter().filter(|&&o| o).count();
                for (p, &o) in g3.iter().zip(&open) {
                    if o {
                        lv[MAX_K - 1].push(*p);
                    }
                }
                if open[n3 / 2] {
                    lv[0].push(g3[n3 / 2]);
                }
                // A contact edge can cross a corner without touching the 3×3 points: probe
                // the corners too (pulled 2 % towards the centroid).
                let (corners, nc) = e.corners(&mesh.positions);
                let corner_covered = open3 == n3
                    && corners[..nc].iter().any(|c| {
                        covered(*c + (e.centroid - *c) * 0.02, e.normal, e.patch, &probe, &mut cast)
                    });
                if open3 == n3 && !corner_covered {
                    lv[1] = grid(e, &mesh.positions, 2);
                } else if open3 > 0 {
                    lv[1] = grid(e, &mesh.positions, 2)
                        .into_iter()
                        .filter(|&p| !covered(p, e.normal, e.patch, &probe, &mut cast))
                        .collect();
                }
                // A mixed 3×3 result means a contact edge crosses the element: estimate the
                // open fraction on a finer grid (reciprocity depends on it).
                // Near such an edge the exchange with the touching surface is singular, so the
                // finest receiver set becomes the open points of that grid too.
                let open3_pts = lv[MAX_K - 1].clone();
                let mut frac = open3 as f64 / n3 as f64;
                let mut cells = if open3 == 0 { 0 } else { u64::MAX };
                // Elements small beside the scene (below `FINE_SIZE` of its diagonal: the
                // parts of furniture, not the floor they stand on) keep the 3 × 3 verdict:
                // the fine grid's 64 points would cost most of the probes on a large model
                // for a share of the scene's area that the 3 × 3 grid resolves well enough.
                let fine_grid = e.area.sqrt() >= FINE_SIZE * diag;
                // Whether the fine grid decided the open cells (it found some open).
                let mut fine_decided = false;
                let mut fine_open = Vec::new();
                if open3 > 0 && (open3 < n3 || corner_covered) && fine_grid {
                    let fine = grid(e, &mesh.positions, FINE_K);
                    let mut mask = 0u64;
                    for (b, p) in fine.iter().enumerate() {
                        if !covered(*p, e.normal, e.patch, &probe, &mut cast) {
                            mask |= 1 << b;
                            fine_open.push(*p);
                        }
                    }
                    if !fine_open.is_empty() {
                        lv[MAX_K - 1] = std::mem::take(&mut fine_open);
                        cells = mask;
                        fine_decided = true;
                        if mask == u64::MAX {
                            frac = 1.0;
                        }
                    } else {
                        // The fine grid found nothing open (a sliver around a 3 × 3
                        // point): the 3 × 3 verdict below.
                        cells = 0;
                    }
                }
                if open3 > 0 && open3 < n3 && !fine_decided {
                    // The fine cells whose centres lie in an open 3 × 3 cell. (Small
                    // elements too: left at "all cells open" with an open fraction of
                    // open3/9, the adaptive factors integrated the whole element and divided
                    // by its open area, raw rows up to 9.0 in office2's luminaires, issue 9.)
                    cells = 0;
                    for b in 0..FINE_K * FINE_K {
                        let (u, v) =
                            (((b % FINE_K) as f64 + 0.5) / FINE_K as f64, ((b / FINE_K) as f64 + 0.5) / FINE_K as f64);
                        let k = ((v * MAX_K as f64) as usize).min(MAX_K - 1) * MAX_K
                            + ((u * MAX_K as f64) as usize).min(MAX_K - 1);
                        if open[k] {
                            cells |= 1 << b;
                        }
                    }
                }
                // k = 1: the centroid when the whole element is open, else the open point
                // nearest the centre of the open part.
                lv[0] = if open3 == n3 {
                    vec![e.centroid]
                } else {
                    let pool = if open3_pts.is_empty() { &lv[MAX_K - 1] } else { &open3_pts };
                    if pool.is_empty() {
                        Vec::new()
                    } else {
                        let c = pool.iter().copied().sum::<DVec3>() / pool.len() as f64;
                        let best = pool
                            .iter()
                            .copied()
                            .min_by(|a, b| (*a - c).length_squared().total_cmp(&(*b - c).length_squared()));
                        best.into_iter().collect()
                    }
                };
                if lv[1].is_empty() {
                    lv[1] = lv[MAX_K - 1].clone();
                }
                // An element wholly inside closed geometry still gets receiver points (all
                // of them): it has no open area, so it sends no power, but its radiosity is
                // what the inside of the solid sees — in a two-sided furnace, the faces of
                // one box inside another must still read E/(1 − ρ), not E (issue 9).
                if open3 == 0 && lv.iter().all(|l| l.is_empty()) {
                    for (k, l) in lv.iter_mut().enumerate() {
                        *l = grid(e, &mesh.positions, k + 1);
                    }
                    lv[0] = vec![e.centroid];
                }
                // Cells of a quad that is not a parallelogram differ in area: the open
                // fraction of a partly covered element is the area of its open polygons,
                // so that every method divides by the area it integrates over.
                if cells != 0 && cells != u64::MAX && e.area > 0.0 {
                    let a: f64 = open_polygons(e, &mesh.positions, cells).iter().map(|q| 0.5 * newell_normal(q).length()).sum();
                    frac = (a / e.area).clamp(0.0, 1.0);
                }
                (lv, frac, cells, cast)
            })
            .collect();
        progress.end();
        let mut points = Vec::with_capacity(res.len());
        let mut open_fraction = Vec::with_capacity(res.len());
        let mut open_cells = Vec::with_capacity(res.len());
        let mut rays = 0;
        for (p, f, c, r) in res {
            rays += r;
            points.push(p);
            open_fraction.push(f);
            open_cells.push(c);
        }
        Receivers { points, open_fraction, open_cells, rays, sides: probe.sides }
    }
}

/// The polygons of [`Receivers::open_pieces`] for the open-cell `mask` of element `el`.
pub fn open_polygons(el: &super::Element, positions: &[DVec3], m: u64) -> Vec<Vec<DVec3>> {
    let k = FINE_K as f64;
    let runs = |j: usize| {
        let mut out = Vec::new();
        let mut i = 0;
        while i < FINE_K {
            if m & (1 << (j * FINE_K + i)) != 0 {
                let i0 = i;
                while i < FINE_K && m & (1 << (j * FINE_K + i)) != 0 {
                    i += 1;
                }
                out.push((i0, i));
            } else {
                i += 1;
            }
        }
        out
    };
    let mut rects = Vec::new();
    // (i0, i1, first row) of the rectangles still growing.
    let mut open: Vec<(usize, usize, usize)> = Vec::new();
    for j in 0..=FINE_K {
        let row = if j < FINE_K { runs(j) } else { Vec::new() };
        open.retain(|&(i0, i1, j0)| {
            let go_on = row.contains(&(i0, i1));
            if !go_on {
                rects.push((i0, i1, j0, j));
            }
            go_on
        });
        for r in row {
            if !open.iter().any(|&(i0, i1, _)| (i0, i1) == r) {
                open.push((r.0, r.1, j));
            }
        }
    }
    rects
        .into_iter()
        .map(|(i0, i1, j0, j1)| {
            let (u0, u1, v0, v1) = (i0 as f64 / k, i1 as f64 / k, j0 as f64 / k, j1 as f64 / k);
            let mut p: Vec<DVec3> = [(u0, v0), (u1, v0), (u1, v1), (u0, v1)].iter().map(|&(u, v)| el.point(positions, u, v)).collect();
            // A triangle's u = 0 edge is its first corner: two corners coincide.
            p.dedup();
            if p.len() > 1 && p.first() == p.last() {
                p.pop();
            }
            p
        })
        .filter(|p| p.len() >= 3)
        .collect()
}

/// The [`FINE_K`] × [`FINE_K`] cell of (u, v).
#[inline]
fn cell(u: f64, v: f64) -> u32 {
    let k = FINE_K as f64;
    let i = ((u * k) as usize).min(FINE_K - 1);
    let j = ((v * k) as usize).min(FINE_K - 1);
    (j * FINE_K + i) as u32
}

/// Midpoints of the k × k grid in the element's parameter domain.
fn grid(e: &super::Element, positions: &[DVec3], k: usize) -> Vec<DVec3> {
    let mut v = Vec::with_capacity(k * k);
    for j in 0..k {
        for i in 0..k {
            v.push(e.point(positions, (i as f64 + 0.5) / k as f64, (j as f64 + 0.5) / k as f64));
        }
    }
    v
}

/// What the probes of [`covered`] read: the scene, its rays, its diagonal, and which
/// polygons are lone emitters ([`lone_emitters`]).
struct Probe<'a> {
    scene: &'a Scene,
    rays: &'a SceneRays,
    diag: f64,
    lone_emitter: Vec<bool>,
    /// [`Receivers::sides`].
    sides: Vec<Side>,
}

/// True when a probe that meets polygon `q` (the side facing it) meets the inside of a
/// solid: the generated back copy of a two-sided polygon (behind its input winding's
/// front), unless light showed the pair's sides otherwise (`sides`, from
/// [`super::lit_sides::sides`]). (The back of a one-sided surface is told by the probe's
/// direction.)
pub fn solid_side(scene: &Scene, sides: &[Side], q: u32) -> bool {
    match sides.get(q as usize) {
        Some(Side::Air) => false,
        Some(Side::Solid) => true,
        _ => scene.polygons[q as usize].back_side,
    }
}

/// An undirected edge between two vertices, equal for vertices equal up to rounding (and
/// ±0), as the mesher's are.
pub(super) type EdgeKey = ([u64; 3], [u64; 3]);

/// The [`EdgeKey`] of the edge `a`–`b` (either way round).
pub(super) fn edge_key(a: DVec3, b: DVec3) -> EdgeKey {
    let (ka, kb) = (a.to_array().map(super::uniform::round_key), b.to_array().map(super::uniform::round_key));
    if ka <= kb { (ka, kb) } else { (kb, ka) }
}

/// Per polygon: true for an emitter with an edge that no other input polygon shares (a
/// lamp quad hung on its own, not a face of a closed solid). The back copy of such a
/// polygon is a surface that emits, not the inside of a solid.
fn lone_emitters(scene: &Scene) -> Vec<bool> {
    use std::collections::HashMap;
    let emits = |p: &crate::scene::Polygon| scene.materials[p.material as usize].is_emitter();
    if !scene.polygons.iter().any(|p| p.back_side && emits(p)) {
        return vec![false; scene.polygons.len()];
    }
    let mut count: HashMap<EdgeKey, u32> = HashMap::new();
    for p in scene.polygons.iter().filter(|p| !p.back_side) {
        let v = &p.vertices;
        for k in 0..v.len() {
            *count.entry(edge_key(v[k], v[(k + 1) % v.len()])).or_default() += 1;
        }
    }
    scene
        .polygons
        .iter()
        .map(|p| {
            let v = &p.vertices;
            emits(p) && (0..v.len()).any(|k| count.get(&edge_key(v[k], v[(k + 1) % v.len()])).is_none_or(|&c| c <= 1))
        })
        .collect()
}

/// True when every probe ray from `p` hits a back face first.
fn covered(p: DVec3, n: DVec3, patch: u32, probe: &Probe, cast: &mut u64) -> bool {
    covered_at(p, n, patch, probe, cast, false)
}

/// [`covered`]; `nested` for the check of a lone emitter's back copy (no further nesting).
fn covered_at(p: DVec3, n: DVec3, patch: u32, probe: &Probe, cast: &mut u64, nested: bool) -> bool {
    let (scene, diag) = (probe.scene, probe.diag);
    let (t, b) = basis(n);
    let origin = (p + n * (1e-7 * diag)).as_vec3();
    let mut copy_checked = nested;
    for s in 0..PROBES {
        let (u1, u2) = halton2(s, (0.5 / PROBES as f64, 0.25));
        let d = cosine_hemisphere(u1, u2);
        let dir = t * d.x + b * d.y + n * d.z;
        *cast += 1;
        // A hit "from behind" is the back of a one-sided surface, or the generated back
        // copy of a two-sided one (behind its input winding's front): inside a two-sided box
        // counts as inside, as for a one-sided one.
        match probe.rays.closest_facing(origin, dir.as_vec3(), f32::INFINITY, Some(patch)) {
            Some((hit, q)) if solid_side(scene, &probe.sides, q) => {
                // The back copy of a lone emitter (a lamp quad on its own, not a face of
                // a closed solid) emits: the point is inside a solid only if that side is
                // too where the probe meets it. A two-sided lamp 0.01 under a ceiling
                // (McGuire's Cornell box light, RenderPark's cube) has its back copy open
                // (it sees the ceiling's front), so the ceiling above it is open too;
                // covered, it took the light that the lamp's back emits and counted it
                // escaped (McGuire `--two-sided`: 44.6 % escaped against 18.3 % by rays;
                // the closed cube 35 % against 0). Back copies of faces of closed solids
                // keep the rule: checked too, the part of a box inside another (the
                // interpenetrating furnace boxes) and the undersides of the conference
                // room's furniture opened up.
                if !copy_checked && probe.lone_emitter[q as usize] {
                    copy_checked = true;
                    let h = origin.as_dvec3() + dir * f64::from(hit.t);
                    if !covered_at(h, scene.polygons[q as usize].normal, q, probe, cast, true) {
                        return false;
                    }
                }
            }
            Some((_, q)) if scene.polygons[q as usize].normal.dot(dir) > 0.0 => {}
            _ => return false,
        }
    }
    true
}
