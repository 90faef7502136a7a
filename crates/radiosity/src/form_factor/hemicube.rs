//! The hemicube (Cohen & Greenberg 1985, "The hemi-cube: a radiosity solution for complex
//! environments").
//!
//! ```text
//! F_ij ≈ Σ_{pixels p of the hemicube at i's centre showing j} ΔF_p
//! ```
//!
//! A half cube of half-width 1 stands on the sender's centre, oriented by its normal: a
//! `res × res` top face and four `res × res/2` side faces. Every element in front of the
//! sender is projected onto the five faces and scan-converted with a depth test into an
//! item buffer (one element id per pixel); the form factor to `j` is the sum of the
//! pixels' delta form factors. The classic delta factors are the midpoint values
//! `ΔA / (π (x² + y² + 1)²)` (top) and `z ΔA / (π (y² + z² + 1)²)` (sides); we precompute
//! each pixel's *exact* factor instead (the point-to-polygon contour integral of the pixel
//! square, [`super::analytic::point_factor`]), so the table sums to 1 to rounding and the only error left
//! is the method's own:
//!
//! - **aliasing**: a pixel is all or nothing, so a receiver's factor is quantised to
//!   whole pixels (worst for small or distant receivers and at silhouettes; it averages
//!   out over many senders, which is why per-object factors are much better than single
//!   element pairs);
//! - **the point approximation**: the factor is taken from the sender's centre, so pairs
//!   closer than a few element sizes (neighbours across a shared edge) are off — the
//!   "proximity" error Cohen & Greenberg discuss; subdividing the sender cures it. We do
//!   that where it matters: when anything is nearer the centre than the element's size,
//!   the row is the average of hemicubes on the element's 3 × 3 open points. Without it,
//!   the housing around office2's small lamp received 1.7× its true direct light and the
//!   scene's rows gathered 1.10× the lamp's power (energy created; every surface +9 %).
//!   Even 3 × 3 hemicubes resolve a step in the factor only to a third of an element (a
//!   lamp 0.01 under a ceiling), so near pairs take the exact unoccluded factor times the
//!   visible share the hemicubes saw (Baum, Rushmeier & Winget 1989, "Improving radiosity
//!   solutions through the use of analytically determined form-factors"; see
//!   `Rows::near_pairs_exactly`).
//!
//! Both are measured in BENCHMARKS.md (`## Form factors`) against the closed forms. Back
//! faces of one-sided polygons block but receive nothing; back faces of two-sided
//! polygons are skipped (their coincident front twin is drawn).

use glam::{DVec2, DVec3};

use super::kernel::{point_to_polygon, point_to_polygon_unsided};
use super::{Context, RowSource};

/// Default pixels along the top face.
pub const DEFAULT_RESOLUTION: usize = 128;

/// The delta form factors of one resolution.
#[derive(Clone, Debug)]
pub struct DeltaTable {
    /// Pixels along the top face.
    pub res: usize,
    /// Top face, row-major `res × res`, pixel (ix, iy) covers `x, y ∈ [−1 + k·2/res, ...]`.
    pub top: Vec<f64>,
    /// One side face (the four are the same), row-major `res × res/2`: column `iu` along the
    /// face, row `iv` the height `z ∈ [iv·2/res, (iv+1)·2/res]`.
    pub side: Vec<f64>,
}

impl DeltaTable {
    /// Exact per-pixel factors for `res` (even).
    pub fn new(res: usize) -> Self {
        let d = 2.0 / res as f64;
        let h = res / 2;
        let mut top = vec![0.0; res * res];
        let mut side = vec![0.0; res * h];
        let o = DVec3::ZERO;
        // By symmetry only one quadrant (one half of a side) needs the contour integral.
        for iy in 0..res {
            for ix in 0..res {
                if ix >= h || iy >= h {
                    continue;
                }
                let (x0, y0) = (-1.0 + ix as f64 * d, -1.0 + iy as f64 * d);
                let sq = [
                    DVec3::new(x0, y0, 1.0),
                    DVec3::new(x0 + d, y0, 1.0),
                    DVec3::new(x0 + d, y0 + d, 1.0),
                    DVec3::new(x0, y0 + d, 1.0),
                ];
                let f = point_to_polygon_unsided(o, DVec3::Z, &sq);
                for (jx, jy) in [(ix, iy), (res - 1 - ix, iy), (ix, res - 1 - iy), (res - 1 - ix, res - 1 - iy)] {
                    top[jy * res + jx] = f;
                }
            }
        }
        for iv in 0..h {
            for iu in 0..h {
                let (u0, z0) = (-1.0 + iu as f64 * d, iv as f64 * d);
                let sq = [
                    DVec3::new(1.0, u0, z0),
                    DVec3::new(1.0, u0 + d, z0),
                    DVec3::new(1.0, u0 + d, z0 + d),
                    DVec3::new(1.0, u0, z0 + d),
                ];
                let f = point_to_polygon_unsided(o, DVec3::Z, &sq);
                side[iv * res + iu] = f;
                side[iv * res + (res - 1 - iu)] = f;
            }
        }
        DeltaTable { res, top, side }
    }

    /// Sum of all five faces' factors (1 up to rounding).
    pub fn total(&self) -> f64 {
        self.top.iter().sum::<f64>() + 4.0 * self.side.iter().sum::<f64>()
    }
}

/// Face `f` maps local (x, y, z) (z along the sender normal) to (U, V, D): the pixel is at
/// (U/D, V/D) and D is the depth. Face 0 is the top.
#[inline]
fn to_face(f: usize, p: DVec3) -> DVec3 {
    match f {
        0 => p,
        1 => DVec3::new(p.y, p.z, p.x),
        2 => DVec3::new(p.y, p.z, -p.x),
        3 => DVec3::new(p.x, p.z, p.y),
        _ => DVec3::new(p.x, p.z, -p.y),
    }
}

pub(crate) struct Rows<'a> {
    ctx: &'a Context<'a>,
    table: DeltaTable,
    two_sided: Vec<bool>,
    /// Per patch: it overlaps a coincident same-facing twin ([`Context::twins`], either
    /// side of the pair). The depth test shares their overlap between them pixel by
    /// pixel, so the exact factor of either alone would count it twice.
    twinned: Vec<bool>,
}

impl<'a> Rows<'a> {
    pub fn new(ctx: &'a Context<'a>) -> Self {
        let scene = ctx.scene;
        let two_sided =
            scene.polygons.iter().map(|p| scene.materials[p.material as usize].two_sided).collect();
        let mut twinned: Vec<bool> = ctx.twins.iter().map(|t| !t.is_empty()).collect();
        for t in ctx.twins.iter().flatten() {
            twinned[*t as usize] = true;
        }
        Rows { ctx, table: DeltaTable::new(ctx.opts.hemicube_resolution), two_sided, twinned }
    }
}

/// Item and inverse-depth buffers of the five faces, accumulation, clip buffers.
pub(crate) struct Scratch {
    ids: Vec<u32>,
    inv_depth: Vec<f64>,
    acc: Vec<f64>,
    touched: Vec<u32>,
    patches: Vec<u32>,
    cached: u32,
    a: Vec<DVec3>,
    b: Vec<DVec3>,
    /// The row being corrected, as [`super::settle_far_field`] takes it
    /// ([`Rows::near_pairs_exactly`]).
    row: Vec<(u32, f64, bool, f64)>,
    exact: super::analytic::Scratch,
}

impl Scratch {
    /// Depth of the nearest thing drawn in the buffers (∞ if none).
    fn nearest(&self) -> f64 {
        let most = self.inv_depth.iter().fold(0.0f64, |m, &w| m.max(w));
        if most > 0.0 {
            1.0 / most
        } else {
            f64::INFINITY
        }
    }
}

const EMPTY: u32 = u32::MAX;
/// Set on an item id drawn from its back side (blocks, receives nothing).
const BACK: u32 = 1 << 31;

impl RowSource for Rows<'_> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        let r = self.table.res;
        let pixels = r * r + 4 * r * (r / 2);
        Scratch {
            ids: vec![EMPTY; pixels],
            inv_depth: vec![0.0; pixels],
            acc: vec![0.0; self.ctx.mesh.len()],
            touched: Vec::new(),
            patches: Vec::new(),
            cached: u32::MAX,
            a: Vec::new(),
            b: Vec::new(),
            row: Vec::new(),
            exact: Default::default(),
        }
    }

    fn row(&self, i: usize, s: &mut Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
        let ctx = self.ctx;
        let mesh = ctx.mesh;
        let ei = &mesh.elements[i];
        if s.cached != ei.patch {
            s.cached = ei.patch;
            patches_in_front(ctx, ei.patch, &mut s.patches);
        }
        // The hemicube stands on the element's open representative point (its centroid
        // unless that lies inside closed geometry); none: the element receives nothing.
        let Some(&c) = ctx.receivers.points(i, 1).first() else {
            return 0;
        };
        self.render(i, c, s);
        let nearest = s.nearest();
        // Proximity: a surface closer to the centre than the element's own size (a wall
        // across a corner, a lamp beside its housing) gets a point factor far from the
        // element's area average — summed over receivers, the excess can exceed what the
        // neighbour emits, i.e. create energy. Average hemicubes over the element's k × k
        // open points instead (Cohen & Greenberg's cure: subdividing the sender).
        let k = ctx.opts.max_receiver_samples.min(crate::mesh::coverage::MAX_K);
        let pts = if k > 1 && nearest < PROXIMITY * ei.area.sqrt() { ctx.receivers.points(i, k) } else { &[] };
        if pts.len() > 1 {
            let w = 1.0 / pts.len() as f64;
            for &p in pts {
                self.render(i, p, s);
                self.accumulate(s, w);
            }
        } else {
            self.accumulate(s, 1.0);
        }
        let start = out.len();
        self.flush(s, out);
        let centre = [c];
        self.near_pairs_exactly(i, if pts.len() > 1 { pts } else { &centre }, &mut out[start..], s);
        0
    }
}

/// A pair is near when the larger element's size (√area) is at least this share of the
/// distance between their centroids: where point-sampled rows take the finest receiver
/// grid ([`super::point_sampled`]).
const NEAR_RATIO: f64 = 0.6;

/// The largest visible share a near pair takes from its hemicubes
/// ([`Rows::near_pairs_exactly`]).
const MAX_SHARE: f64 = 2.0;

impl Rows<'_> {
    /// Near pairs exactly (Baum, Rushmeier & Winget 1989, "Improving radiosity solutions
    /// through the use of analytically determined form-factors": the hemicube where its
    /// assumptions fail). A near element's factor varies across the sender faster than
    /// its hemicubes resolve (a lamp 0.01 under a ceiling is a step over each ceiling
    /// element): where `i` is wholly open and `j` has no coincident twin, `F_ij` becomes the
    /// exact unoccluded factor (double contour integral, [`super::analytic`]; reciprocal)
    /// times the visible share the hemicubes saw, `F_hc / F_unocc` at the same points.
    /// What that adds is taken from the row's far entries as point-sampled rows do
    /// ([`super::settle_far_field`]). RenderPark's closed cube `--two-sided` let 2.88 % of
    /// its light escape through the ceiling above its lamps' back sides.
    fn near_pairs_exactly(&self, i: usize, pts: &[DVec3], out: &mut [(u32, f64)], s: &mut Scratch) {
        let ctx = self.ctx;
        let mesh = ctx.mesh;
        let ei = &mesh.elements[i];
        let k = ctx.opts.max_receiver_samples.min(crate::mesh::coverage::MAX_K);
        if k < 2 || ctx.receivers.points(i, k).len() != k * k || pts.is_empty() {
            return;
        }
        let (ci, ni) = ei.corners(&mesh.positions);
        let size_i = ei.area.sqrt();
        s.row.clear();
        let mut excess = 0.0;
        for &(j, f_hc) in out.iter() {
            let ej = &mesh.elements[j as usize];
            let d = (ej.centroid - ei.centroid).length().max(1e-300);
            if size_i.max(ej.area.sqrt()) < NEAR_RATIO * d || self.twinned[ej.patch as usize] {
                s.row.push((j, f_hc, true, (size_i / d).powi(2)));
                continue;
            }
            let (cj, nj) = ej.corners(&mesh.positions);
            let cj = &cj[..nj];
            let unocc = pts.iter().map(|&x| point_to_polygon(x, ei.normal, cj, ej.normal)).sum::<f64>() / pts.len() as f64;
            let mut f = f_hc;
            if unocc > 0.0 {
                let exact = super::analytic::area_factor_with(&mut s.exact, &ci[..ni], ei.normal, cj, ej.normal) / ei.area;
                // The share is not held to one: the hemicubes' aliasing scatters it about
                // the truth both ways (a cap at one took 0.26 % from office2's near pairs
                // in all), but to two, against a grazing pair whose points see almost
                // nothing of `j`.
                f = exact * (f_hc / unocc).min(MAX_SHARE);
                excess += f - f_hc;
            }
            s.row.push((j, f, false, 0.0));
        }
        super::settle_far_field(&mut s.row, excess);
        for (o, e) in out.iter_mut().zip(&s.row) {
            o.1 = e.1;
        }
    }
}

impl Rows<'_> {
    /// Draws every element in front of element `i` into the five faces of a hemicube
    /// standing on `c`.
    fn render(&self, i: usize, c: DVec3, s: &mut Scratch) {
        let ctx = self.ctx;
        let mesh = ctx.mesh;
        let ei = &mesh.elements[i];
        s.ids.fill(EMPTY);
        s.inv_depth.fill(0.0);
        let (t, b) = crate::sampling::basis(ei.normal);
        let n = ei.normal;
        let local = |p: DVec3| {
            let d = p - c;
            DVec3::new(d.dot(t), d.dot(b), d.dot(n))
        };
        let near = 1e-12 * ctx.scene.diagonal().max(1e-300);
        let patches = std::mem::take(&mut s.patches);
        for &q in &patches {
            let pe = mesh.patches[q as usize];
            let facing = ctx.planes[q as usize].1.dot(c - ctx.planes[q as usize].0) > 0.0;
            if !facing && self.two_sided[q as usize] {
                continue;
            }
            let flag = if facing { 0 } else { BACK };
            for j in pe.first..pe.first + pe.count {
                let ej = &mesh.elements[j as usize];
                let (cj, nv) = ej.corners(&mesh.positions);
                let mut lp = [DVec3::ZERO; 4];
                let mut any_above = false;
                for k in 0..nv {
                    lp[k] = local(cj[k]);
                    any_above |= lp[k].z > near;
                }
                if !any_above {
                    continue;
                }
                let ln = DVec3::new(ej.normal.dot(t), ej.normal.dot(b), ej.normal.dot(n));
                for f in 0..5 {
                    self.draw(f, &lp[..nv], ln, j | flag, near, s);
                }
            }
        }
        s.patches = patches;
    }

    /// Adds `weight` × the delta factors of the front-facing items in the buffers.
    fn accumulate(&self, s: &mut Scratch, weight: f64) {
        let res = self.table.res;
        let h = res / 2;
        for (k, &id) in s.ids.iter().enumerate() {
            if id == EMPTY || id & BACK != 0 {
                continue;
            }
            let df = if k < res * res {
                self.table.top[k]
            } else {
                let r = (k - res * res) % (res * h);
                self.table.side[r]
            };
            if s.acc[id as usize] == 0.0 {
                s.touched.push(id);
            }
            s.acc[id as usize] += weight * df;
        }
    }

    /// Moves the accumulated factors into the row.
    fn flush(&self, s: &mut Scratch, out: &mut Vec<(u32, f64)>) {
        for &j in &s.touched {
            out.push((j, s.acc[j as usize]));
            s.acc[j as usize] = 0.0;
        }
        s.touched.clear();
    }
}

/// Hemicubes are repeated on the k × k receiver grid (k = `max_receiver_samples`, 3) when a
/// surface is nearer the centre than this many times the square root of the element's area.
/// Measured on office2 (per-object signed error against the path tracer): one hemicube
/// +9.0 %, 2 × 2 −0.6 %, 3 × 3 −0.2 %; 3 × 3 costs 2–4.5× the single hemicube on the
/// Cornell box.
const PROXIMITY: f64 = 1.0;

impl Rows<'_> {
    /// Clips the element (local coordinates `lp`, local normal `ln`) to face `f`'s view
    /// volume and scan-converts it with a depth test.
    fn draw(&self, f: usize, lp: &[DVec3], ln: DVec3, id: u32, near: f64, s: &mut Scratch) {
        let res = self.table.res;
        let top = f == 0;
        // Trivial rejects by outcodes against the face's frustum.
        let mut all_out = [true; 5];
        for p in lp {
            let q = to_face(f, *p);
            let vmin = if top { -q.z } else { 0.0 };
            all_out[0] &= q.z <= near;
            all_out[1] &= q.x > q.z;
            all_out[2] &= q.x < -q.z;
            all_out[3] &= q.y > q.z;
            all_out[4] &= q.y < vmin;
        }
        if all_out.iter().any(|&o| o) {
            return;
        }
        s.a.clear();
        s.a.extend(lp.iter().map(|p| to_face(f, *p)));
        // Clip to D ≥ near, |U| ≤ D, V ≤ D, V ≥ −D (top) or V ≥ 0 (sides).
        let planes: [(DVec3, f64); 5] = [
            (DVec3::new(0.0, 0.0, 1.0), -near),
            (DVec3::new(-1.0, 0.0, 1.0), 0.0),
            (DVec3::new(1.0, 0.0, 1.0), 0.0),
            (DVec3::new(0.0, -1.0, 1.0), 0.0),
            if top { (DVec3::new(0.0, 1.0, 1.0), 0.0) } else { (DVec3::new(0.0, 1.0, 0.0), 0.0) },
        ];
        for (pn, off) in planes {
            super::geom::clip_halfspace(&s.a, |p| pn.dot(p) + off, 0.0, &mut s.b);
            std::mem::swap(&mut s.a, &mut s.b);
            if s.a.is_empty() {
                return;
            }
        }
        // Inverse depth 1/D is affine in (u, v): with the plane m·P = h (face coordinates),
        // a pixel ray P = D·(u, v, 1) meets it at 1/D = (m_u u + m_v v + m_d) / h.
        let m = to_face(f, ln);
        let hp = m.dot(s.a[0]);
        if hp.abs() <= 0.0 {
            return; // seen edge-on
        }
        let (au, av, ad) = (m.x / hp, m.y / hp, m.z / hp);
        let mut pts = [DVec2::ZERO; 16];
        let np = s.a.len().min(16);
        for k in 0..np {
            let p = s.a[k];
            pts[k] = DVec2::new(p.x / p.z, p.y / p.z);
        }
        let pts = &pts[..np];
        let d = 2.0 / res as f64;
        let (rows, v0, base) = if top { (res, -1.0, 0) } else { (res / 2, 0.0, res * res + (f - 1) * res * (res / 2)) };
        let (mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in pts {
            vmin = vmin.min(p.y);
            vmax = vmax.max(p.y);
        }
        let iy0 = (((vmin - v0) / d - 0.5).ceil().max(0.0)) as usize;
        let iy1 = ((((vmax - v0) / d - 0.5).floor()) as i64).min(rows as i64 - 1);
        if iy1 < iy0 as i64 {
            return;
        }
        for iy in iy0..=iy1 as usize {
            let vc = v0 + (iy as f64 + 0.5) * d;
            // Span of the convex polygon on this scanline.
            let (mut ul, mut ur) = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..np {
                let (p, q) = (pts[k], pts[(k + 1) % np]);
                if (p.y <= vc && q.y >= vc) || (q.y <= vc && p.y >= vc) {
                    let u = if q.y == p.y { p.x.min(q.x) } else { p.x + (q.x - p.x) * (vc - p.y) / (q.y - p.y) };
                    let u2 = if q.y == p.y { p.x.max(q.x) } else { u };
                    ul = ul.min(u);
                    ur = ur.max(u2);
                }
            }
            if !(ul <= ur) {
                continue;
            }
            // Pixel centres in [ul, ur).
            let ix0 = (((ul + 1.0) / d - 0.5).ceil().max(0.0)) as usize;
            let ix1 = (((ur + 1.0) / d - 0.5).ceil() as i64 - 1).min(res as i64 - 1);
            if ix1 < ix0 as i64 {
                continue;
            }
            let row = base + iy * res;
            for ix in ix0..=ix1 as usize {
                let uc = -1.0 + (ix as f64 + 0.5) * d;
                let w = au * uc + av * vc + ad;
                let k = row + ix;
                if w > s.inv_depth[k] {
                    s.inv_depth[k] = w;
                    s.ids[k] = id;
                }
            }
        }
    }
}

/// Patches with some vertex strictly in front of patch `pi`'s plane (everything that can
/// be seen from it, facing it or not).
fn patches_in_front(ctx: &Context, pi: u32, out: &mut Vec<u32>) {
    out.clear();
    let (ci, ni) = ctx.planes[pi as usize];
    for (q, poly) in ctx.scene.polygons.iter().enumerate() {
        if q as u32 != pi && poly.vertices.iter().any(|v| ni.dot(*v - ci) > ctx.eps) {
            out.push(q as u32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_delta_factors_sum_to_one() {
        for res in [2, 8, 64] {
            let t = DeltaTable::new(res);
            assert!((t.total() - 1.0).abs() < 1e-13, "res {res}: {}", t.total());
        }
        // The classic midpoint value is close for a small pixel near the zenith.
        let t = DeltaTable::new(256);
        let d: f64 = 2.0 / 256.0;
        let x = -1.0 + 128.5 * d;
        let mid = d * d / (std::f64::consts::PI * (x * x + x * x + 1.0).powi(2));
        assert!((t.top[128 * 256 + 128] - mid).abs() < 1e-4 * mid);
    }
}
