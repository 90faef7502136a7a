//! A lightmap atlas: every polygon mapped, without distortion, into a square texture.
//!
//! **Charts.** Polygons that lie in one plane and share edges start as one chart (two
//! triangles of a glTF quad, the tiles of a floor, a wall split between objects): union–find
//! over shared edges (vertex positions equal to 1e-9 of the scene's size), same plane
//! (normals within 1e-6, offsets within 1e-6 of the scene's size), projected orthographically
//! onto their plane. Charts then grow across bends, as xatlas's do, but without distortion: a
//! chart joins a neighbour by turning about their shared edge into the neighbour's plane (a
//! hinge, so lengths and angles are kept; the four sides of a table leg become one strip),
//! longest shared edges first, if it then lies at least two paddings away from every polygon
//! of the neighbour that it does not touch in space and if the joined chart's padded
//! rectangle takes no more texels than the two separate ones. Every polygon keeps its own
//! isometric [`Frame`] into its chart, so every chart has the same texel size in world
//! units: density is uniform by construction. Each chart is finally turned to its smallest
//! bounding rectangle (rotating calipers over its convex hull).
//!
//! **Packing.** Each chart's bounding rectangle, grown by `padding` texels on every side
//! (texels there are filled by dilation, so bilinear filtering never reads an empty one),
//! is placed by a guillotine allocator (the `guillotiere` crate; measured against `etagere`'s
//! shelf allocators, BENCHMARKS.md "Lightmaps": of 30 000 rectangles filling 90 % of the
//! square, guillotiere placed all in 0.19 s, etagere 37–39 %), tallest first. The texel
//! size is chosen so that the rectangles fill about 80 % of the texture, then grown by 5 %
//! until everything fits.

use std::collections::HashMap;

use glam::{DVec2, DVec3};

use crate::scene::Scene;
use crate::{Error, Result};

/// Texels of padding around every chart by default.
pub const DEFAULT_PADDING: usize = 2;

/// Lightmap side in texels by default.
pub const DEFAULT_SIZE: usize = 1024;

/// Share of the texture the charts' rectangles aim at when the texel size is automatic.
const TARGET_FILL: f64 = 0.95;

/// How to build the atlas.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Side of the square texture, texels.
    pub size: usize,
    /// World units per texel; None: as small as fits (see the module docs).
    pub texel: Option<f64>,
    /// Texels around each chart.
    pub padding: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options { size: DEFAULT_SIZE, texel: None, padding: DEFAULT_PADDING }
    }
}

/// One chart: edge-connected polygons (same side) laid flat without distortion.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Scene polygons.
    pub polygons: Vec<u32>,
    /// Rectangle size in texels, padding included.
    pub width: usize,
    /// Rectangle height in texels, padding included.
    pub height: usize,
    /// Top-left texel of the rectangle in the atlas.
    pub x: usize,
    /// Top-left texel row.
    pub y: usize,
}

/// Where one polygon lies in its chart: chart coordinates (world units, from the chart's
/// corner) of a point `p` of the polygon are `((p − origin)·u, (p − origin)·v)`. `u` and `v`
/// are orthonormal in the polygon's plane, so the map is an isometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// The point of the polygon's plane at the chart's corner.
    pub origin: DVec3,
    /// First axis.
    pub u: DVec3,
    /// Second axis.
    pub v: DVec3,
}

impl Frame {
    /// Chart coordinates of `p`.
    #[inline]
    pub fn at(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }

    /// The frame after a rotation by `angle` and a translation by `t` of the chart's plane.
    fn moved(&self, angle: f64, t: DVec2) -> Frame {
        let (s, c) = angle.sin_cos();
        let u = self.u * c - self.v * s;
        let v = self.u * s + self.v * c;
        Frame { origin: self.origin - u * t.x - v * t.y, u, v }
    }
}

/// Charts packed into a square texture.
#[derive(Clone, Debug)]
pub struct Atlas {
    /// Side of the texture, texels.
    pub size: usize,
    /// World units per texel (every chart).
    pub texel: f64,
    /// Texels of padding around each chart.
    pub padding: usize,
    /// The charts.
    pub charts: Vec<Chart>,
    /// Chart of every scene polygon.
    pub chart_of: Vec<u32>,
    /// Every scene polygon's place in its chart.
    pub frames: Vec<Frame>,
}

impl Atlas {
    /// Continuous texel coordinates (texel centres at +0.5) of the world point `p` on
    /// polygon `polygon`.
    #[inline]
    pub fn texel_coords(&self, polygon: u32, p: DVec3) -> (f64, f64) {
        let c = &self.charts[self.chart_of[polygon as usize] as usize];
        let q = self.frames[polygon as usize].at(p);
        let pad = self.padding as f64;
        (c.x as f64 + pad + q.x / self.texel, c.y as f64 + pad + q.y / self.texel)
    }

    /// Normalised texture coordinates (glTF: origin at the image's top-left) of `p` on
    /// polygon `polygon`.
    #[inline]
    pub fn uv(&self, polygon: u32, p: DVec3) -> (f64, f64) {
        let (x, y) = self.texel_coords(polygon, p);
        (x / self.size as f64, y / self.size as f64)
    }

    /// The world point of polygon `polygon`'s plane at continuous texel coordinates (x, y).
    #[inline]
    pub fn world(&self, polygon: u32, x: f64, y: f64) -> DVec3 {
        let ch = &self.charts[self.chart_of[polygon as usize] as usize];
        let f = &self.frames[polygon as usize];
        let pad = self.padding as f64;
        f.origin + f.u * ((x - ch.x as f64 - pad) * self.texel) + f.v * ((y - ch.y as f64 - pad) * self.texel)
    }

    /// Share of the texture inside the charts' rectangles (padding included).
    pub fn used(&self) -> f64 {
        let a: usize = self.charts.iter().map(|c| c.width * c.height).sum();
        a as f64 / (self.size * self.size) as f64
    }

    /// Share of the texture the polygons cover (their area in texels).
    pub fn covered(&self, scene: &Scene) -> f64 {
        let a: f64 = self.charts.iter().flat_map(|c| &c.polygons).map(|&p| scene.polygons[p as usize].area).sum();
        a / (self.texel * self.texel) / (self.size * self.size) as f64
    }

    /// Builds the atlas of every polygon of `scene`.
    pub fn build(scene: &Scene, opts: &Options) -> Result<Atlas> {
        if opts.size < 8 || opts.size > 16384 {
            return Err(Error::Invalid(format!("lightmap size {} must be between 8 and 16384 texels", opts.size)));
        }
        if let Some(t) = opts.texel {
            if !(t.is_finite() && t > 0.0) {
                return Err(Error::Invalid(format!("texel size {t} must be a positive number")));
            }
        }
        let pad = opts.padding;
        let n2 = (opts.size * opts.size) as f64;
        let groups = charts(scene);
        // The unfolding keeps two paddings between polygons of a chart at an expected texel
        // size; if packing then needs larger texels, unfold again at that size.
        let mut expected = match opts.texel {
            Some(t) => t,
            None => {
                let extents: Vec<DVec2> = Flat::new(scene, &groups).live().map(FlatChart::extent).collect();
                auto_texel(&extents, pad, TARGET_FILL * n2)
            }
        };
        for _ in 0..4 {
            let mut flat = Flat::new(scene, &groups);
            flat.unfold(scene, expected, pad);
            flat.fit_rectangles();
            let atlas = flat.pack(scene, opts)?;
            if opts.texel.is_some() || atlas.texel <= expected * (1.0 + 1e-9) {
                return Ok(atlas);
            }
            expected = atlas.texel;
        }
        Err(Error::Invalid(format!("the charts do not fit a {}² lightmap: raise --lightmap-size", opts.size)))
    }
}

impl Flat {
    /// Packs the charts: the texel size (given, or as small as fits), the rectangles.
    fn pack(self, scene: &Scene, opts: &Options) -> Result<Atlas> {
        let pad = opts.padding;
        let n2 = (opts.size * opts.size) as f64;
        let live: Vec<usize> = (0..self.charts.len()).filter(|&c| self.charts[c].alive).collect();
        let extents: Vec<DVec2> = live.iter().map(|&c| self.charts[c].extent()).collect();
        let floor: f64 = (live.len() * (1 + 2 * pad) * (1 + 2 * pad)) as f64;
        if floor > 0.95 * n2 {
            return Err(Error::Invalid(format!(
                "{} charts need at least {} texels with their padding, more than a {}² lightmap holds: \
                 raise --lightmap-size or bake vertex colours",
                live.len(),
                floor,
                opts.size
            )));
        }
        let mut texel = opts.texel.unwrap_or_else(|| auto_texel(&extents, pad, TARGET_FILL * n2));
        for _ in 0..100 {
            let r: Vec<(usize, usize)> = extents.iter().map(|e| padded(*e, texel, pad)).collect();
            if let Some(at) = pack(&r, opts.size) {
                let mut chart_of = vec![u32::MAX; scene.polygons.len()];
                let charts: Vec<Chart> = live
                    .iter()
                    .zip(r.iter().zip(at))
                    .enumerate()
                    .map(|(k, (&c, ((w, h), (x, y))))| {
                        for &p in &self.charts[c].polygons {
                            chart_of[p as usize] = k as u32;
                        }
                        Chart { polygons: self.charts[c].polygons.clone(), width: *w, height: *h, x, y }
                    })
                    .collect();
                return Ok(Atlas { size: opts.size, texel, padding: pad, charts, chart_of, frames: self.frames });
            }
            if opts.texel.is_some() {
                return Err(Error::Invalid(format!(
                    "the charts at texel size {texel} do not fit a {}² lightmap: raise --lightmap-size or --texel-size",
                    opts.size
                )));
            }
            texel *= 1.02;
        }
        Err(Error::Invalid(format!("the charts do not fit a {}² lightmap: raise --lightmap-size", opts.size)))
    }
}

/// Rectangle of a chart of `extent` (world units) in texels, padding included.
fn padded(extent: DVec2, texel: f64, pad: usize) -> (usize, usize) {
    let w = ((extent.x / texel).ceil() as usize).max(1) + 2 * pad;
    let h = ((extent.y / texel).ceil() as usize).max(1) + 2 * pad;
    (w, h)
}

/// The texel size at which rectangles of these extents (world units), padded, fill `target`
/// texels.
fn auto_texel(extents: &[DVec2], pad: usize, target: f64) -> f64 {
    let area: f64 = extents.iter().map(|e| e.x * e.y).sum();
    let mut t = (area.max(f64::MIN_POSITIVE) / target).sqrt();
    for _ in 0..30 {
        let need: usize = extents.iter().map(|e| padded(*e, t, pad)).map(|(w, h)| w * h).sum();
        let ratio = need as f64 / target;
        if (ratio - 1.0).abs() < 0.01 {
            break;
        }
        t *= ratio.sqrt();
    }
    t
}

/// A chart being built: its polygons, their outlines in chart coordinates and their bounds.
struct FlatChart {
    polygons: Vec<u32>,
    lo: DVec2,
    hi: DVec2,
    alive: bool,
}

impl FlatChart {
    fn extent(&self) -> DVec2 {
        (self.hi - self.lo).max(DVec2::ZERO)
    }
}

/// Charts in the making: every polygon's frame and outline.
struct Flat {
    charts: Vec<FlatChart>,
    chart_of: Vec<u32>,
    frames: Vec<Frame>,
    outline: Vec<Vec<DVec2>>,
}

impl Flat {
    /// One chart per coplanar group, projected orthographically onto its plane.
    fn new(scene: &Scene, groups: &[Vec<u32>]) -> Flat {
        let n = scene.polygons.len();
        let mut frames = vec![Frame { origin: DVec3::ZERO, u: DVec3::X, v: DVec3::Y }; n];
        let mut outline = vec![Vec::new(); n];
        let mut chart_of = vec![0u32; n];
        let mut charts = Vec::with_capacity(groups.len());
        for (c, g) in groups.iter().enumerate() {
            let first = &scene.polygons[g[0] as usize];
            let nrm = first.normal;
            let u = nrm.any_orthonormal_vector();
            let v = nrm.cross(u);
            let origin = nrm * nrm.dot(first.vertices[0]);
            let f = Frame { origin, u, v };
            let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
            for &p in g {
                frames[p as usize] = f;
                chart_of[p as usize] = c as u32;
                let o: Vec<DVec2> = scene.polygons[p as usize].vertices.iter().map(|x| f.at(*x)).collect();
                for q in &o {
                    lo = lo.min(*q);
                    hi = hi.max(*q);
                }
                outline[p as usize] = o;
            }
            charts.push(FlatChart { polygons: g.clone(), lo, hi, alive: true });
        }
        Flat { charts, chart_of, frames, outline }
    }

    fn live(&self) -> impl Iterator<Item = &FlatChart> {
        self.charts.iter().filter(|c| c.alive)
    }

    /// Grows charts across bends: a chart joins its neighbour through a shared edge by
    /// turning about that edge into the neighbour's plane (a hinge: lengths and angles
    /// kept), if none of its polygons then comes within two paddings of a polygon of the
    /// neighbour that it does not touch in space, and if the joined chart's padded rectangle
    /// takes no more texels than the two did (at texel size `texel`). Longest shared edges
    /// first.
    fn unfold(&mut self, scene: &Scene, texel: f64, pad: usize) {
        let diag = scene.diagonal().max(f64::MIN_POSITIVE);
        let q = |p: DVec3| -> [i64; 3] { (p / (1e-9 * diag)).round().to_array().map(|x| x as i64) };
        // Edges shared by polygons of different charts, same side.
        let mut first: HashMap<([i64; 3], [i64; 3]), (u32, usize)> = HashMap::new();
        let mut hinges: Vec<(f64, u32, u32, usize, usize)> = Vec::new();
        for (i, p) in scene.polygons.iter().enumerate() {
            let vs = &p.vertices;
            for k in 0..vs.len() {
                let (a, b) = (q(vs[k]), q(vs[(k + 1) % vs.len()]));
                let key = if a < b { (a, b) } else { (b, a) };
                match first.get(&key) {
                    Some(&(j, kj)) => {
                        let o = &scene.polygons[j as usize];
                        if o.back_side == p.back_side && self.chart_of[j as usize] != self.chart_of[i] {
                            let len = (vs[(k + 1) % vs.len()] - vs[k]).length();
                            hinges.push((len, j, i as u32, kj, k));
                        }
                    }
                    None => {
                        first.insert(key, (i as u32, k));
                    }
                }
            }
        }
        hinges.sort_by(|a, b| b.0.total_cmp(&a.0));
        let gap = 2.0 * pad as f64 * texel;
        let padded = |e: DVec2| {
            let (w, h) = padded(e, texel, pad);
            (w * h) as f64
        };
        let vkeys: Vec<Vec<[i64; 3]>> = scene.polygons.iter().map(|p| p.vertices.iter().map(|x| q(*x)).collect()).collect();
        for (_, pa, pb, ka, kb) in hinges {
            let (ca, cb) = (self.chart_of[pa as usize] as usize, self.chart_of[pb as usize] as usize);
            if ca == cb {
                continue;
            }
            // Move the smaller chart onto the larger.
            let (big, small, pbig, psmall, kbig, ksmall) = if self.charts[ca].polygons.len() >= self.charts[cb].polygons.len() {
                (ca, cb, pa, pb, ka, kb)
            } else {
                (cb, ca, pb, pa, kb, ka)
            };
            // The shared edge in both charts' coordinates.
            let vb = &scene.polygons[pbig as usize].vertices;
            let e0 = vb[kbig];
            let e1 = vb[(kbig + 1) % vb.len()];
            let _ = ksmall;
            let (a0, a1) = (self.frames[pbig as usize].at(e0), self.frames[pbig as usize].at(e1));
            let (b0, b1) = (self.frames[psmall as usize].at(e0), self.frames[psmall as usize].at(e1));
            let angle = (a1 - a0).to_angle() - (b1 - b0).to_angle();
            let rot = DVec2::from_angle(angle);
            let t = a0 - rot.rotate(b0);
            // Candidate outlines and bounds.
            let moved: Vec<(u32, Vec<DVec2>)> = self.charts[small]
                .polygons
                .iter()
                .map(|&p| (p, self.outline[p as usize].iter().map(|x| rot.rotate(*x) + t).collect()))
                .collect();
            let (mut lo, mut hi) = (self.charts[big].lo, self.charts[big].hi);
            for (_, o) in &moved {
                for x in o {
                    lo = lo.min(*x);
                    hi = hi.max(*x);
                }
            }
            let before = padded(self.charts[big].extent()) + padded(self.charts[small].extent());
            if padded(hi - lo) > before {
                continue;
            }
            // No overlap, and a gap of two paddings between polygons that do not touch in space.
            let clash = moved.iter().any(|(p, o)| {
                let (olo, ohi) = bounds(o);
                self.charts[big].polygons.iter().any(|&r| {
                    let ro = &self.outline[r as usize];
                    let (rlo, rhi) = bounds(ro);
                    if olo.x > rhi.x + gap || olo.y > rhi.y + gap || rlo.x > ohi.x + gap || rlo.y > ohi.y + gap {
                        return false;
                    }
                    let touch = vkeys[*p as usize].iter().any(|k| vkeys[r as usize].contains(k));
                    !separated(o, ro, if touch { -1e-9 * diag } else { gap })
                })
            });
            if clash {
                continue;
            }
            for (p, o) in moved {
                self.frames[p as usize] = self.frames[p as usize].moved(angle, t);
                self.outline[p as usize] = o;
                self.chart_of[p as usize] = big as u32;
            }
            let ps = std::mem::take(&mut self.charts[small].polygons);
            self.charts[small].alive = false;
            let c = &mut self.charts[big];
            c.polygons.extend(ps);
            c.lo = lo;
            c.hi = hi;
        }
    }

    /// Turns every chart to its smallest bounding rectangle (rotating calipers over the
    /// convex hull of its outlines) and puts its corner at (0, 0).
    fn fit_rectangles(&mut self) {
        for c in 0..self.charts.len() {
            if !self.charts[c].alive {
                continue;
            }
            let pts: Vec<DVec2> = self.charts[c].polygons.iter().flat_map(|&p| self.outline[p as usize].iter().copied()).collect();
            let hull = convex_hull(pts);
            let mut best = (f64::INFINITY, 0.0);
            for i in 0..hull.len() {
                let d = hull[(i + 1) % hull.len()] - hull[i];
                if d.length_squared() <= 0.0 {
                    continue;
                }
                let a = -d.to_angle();
                let r = DVec2::from_angle(a);
                let (lo, hi) = bounds(&hull.iter().map(|x| r.rotate(*x)).collect::<Vec<_>>());
                let area = (hi - lo).x * (hi - lo).y;
                if area < best.0 * (1.0 - 1e-9) {
                    best = (area, a);
                }
            }
            let mut angle = if best.0.is_finite() { best.1 } else { 0.0 };
            let mut r = DVec2::from_angle(angle);
            let (mut lo, mut hi) = bounds(&hull.iter().map(|x| r.rotate(*x)).collect::<Vec<_>>());
            // Lying down (wider than tall): packs tighter, tallest first.
            if (hi - lo).y > (hi - lo).x {
                angle += std::f64::consts::FRAC_PI_2;
                r = DVec2::from_angle(angle);
                (lo, hi) = bounds(&hull.iter().map(|x| r.rotate(*x)).collect::<Vec<_>>());
            }
            for &p in &self.charts[c].polygons {
                self.frames[p as usize] = self.frames[p as usize].moved(angle, -lo);
                for x in &mut self.outline[p as usize] {
                    *x = r.rotate(*x) - lo;
                }
            }
            self.charts[c].lo = DVec2::ZERO;
            self.charts[c].hi = hi - lo;
        }
    }
}

/// Bounds of points.
fn bounds(pts: &[DVec2]) -> (DVec2, DVec2) {
    pts.iter().fold((DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)), |(l, h), p| (l.min(*p), h.max(*p)))
}

/// True if some edge normal of convex polygon `a` or `b` separates them by at least `gap`
/// (a sufficient test that they are at least `gap` apart; a negative gap tolerates touching).
fn separated(a: &[DVec2], b: &[DVec2], gap: f64) -> bool {
    for poly in [a, b] {
        for i in 0..poly.len() {
            let d = poly[(i + 1) % poly.len()] - poly[i];
            if d.length_squared() <= 0.0 {
                continue;
            }
            let n = d.perp().normalize();
            let (amin, amax) = a.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(n.dot(*p)), h.max(n.dot(*p))));
            let (bmin, bmax) = b.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(n.dot(*p)), h.max(n.dot(*p))));
            if bmin - amax >= gap || amin - bmax >= gap {
                return true;
            }
        }
    }
    false
}

/// Convex hull (Andrew's monotone chain), counter-clockwise.
fn convex_hull(mut pts: Vec<DVec2>) -> Vec<DVec2> {
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut h: Vec<DVec2> = Vec::with_capacity(2 * pts.len());
    for &p in &pts {
        while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0.0 {
            h.pop();
        }
        h.push(p);
    }
    let lower = h.len() + 1;
    for &p in pts.iter().rev().skip(1) {
        while h.len() >= lower && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0.0 {
            h.pop();
        }
        h.push(p);
    }
    h.pop();
    h
}

/// Places rectangles in a `size × size` square; their top-left corners in input order, or
/// None if they do not fit. Tries a few orders (tallest first, largest area first, longest
/// side first): with few large charts the order decides whether they fit.
fn pack(rects: &[(usize, usize)], size: usize) -> Option<Vec<(usize, usize)>> {
    if rects.iter().any(|&(w, h)| w > size || h > size) {
        return None;
    }
    type SortKey = fn(&(usize, usize)) -> (usize, usize);
    let keys: [SortKey; 3] =
        [|r| (r.1, r.0), |r| (r.0 * r.1, r.1), |r| (r.0.max(r.1), r.0.min(r.1))];
    'order: for key in keys {
        let mut order: Vec<usize> = (0..rects.len()).collect();
        order.sort_by_key(|&i| std::cmp::Reverse(key(&rects[i])));
        let mut alloc = guillotiere::AtlasAllocator::new(guillotiere::size2(size as i32, size as i32));
        let mut at = vec![(0, 0); rects.len()];
        for i in order {
            let (w, h) = rects[i];
            let Some(a) = alloc.allocate(guillotiere::size2(w as i32, h as i32)) else {
                continue 'order;
            };
            at[i] = (a.rectangle.min.x as usize, a.rectangle.min.y as usize);
        }
        return Some(at);
    }
    None
}

/// Polygons grouped into charts: same plane and side, connected through shared edges.
fn charts(scene: &Scene) -> Vec<Vec<u32>> {
    let n = scene.polygons.len();
    let diag = scene.diagonal().max(f64::MIN_POSITIVE);
    let q = |p: DVec3| -> [i64; 3] { (p / (1e-9 * diag)).round().to_array().map(|x| x as i64) };
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    let mut edges: HashMap<([i64; 3], [i64; 3]), u32> = HashMap::new();
    for (i, p) in scene.polygons.iter().enumerate() {
        let vs = &p.vertices;
        for k in 0..vs.len() {
            let (a, b) = (q(vs[k]), q(vs[(k + 1) % vs.len()]));
            let key = if a < b { (a, b) } else { (b, a) };
            match edges.get(&key) {
                Some(&j) => {
                    let o = &scene.polygons[j as usize];
                    let same_plane = o.back_side == p.back_side
                        && o.normal.dot(p.normal) > 1.0 - 1e-6
                        && (o.normal.dot(o.vertices[0]) - p.normal.dot(vs[0])).abs() < 1e-6 * diag;
                    if same_plane {
                        let (ra, rb) = (find(&mut parent, i as u32), find(&mut parent, j));
                        if ra != rb {
                            parent[ra.max(rb) as usize] = ra.min(rb);
                        }
                    }
                }
                None => {
                    edges.insert(key, i as u32);
                }
            }
        }
    }
    let mut index: HashMap<u32, usize> = HashMap::new();
    let mut out: Vec<Vec<u32>> = Vec::new();
    for i in 0..n as u32 {
        let r = find(&mut parent, i);
        let k = *index.entry(r).or_insert_with(|| {
            out.push(Vec::new());
            out.len() - 1
        });
        out[k].push(i);
    }
    out
}
