//! A lightmap atlas: every polygon mapped, without distortion, into a square texture.
//!
//! **Charts.** Polygons that lie in one plane and share edges form a chart (two triangles
//! of a glTF quad, the tiles of a floor, a wall split between objects; merging across
//! objects took the classroom's surfaces from 26.5 to 29.7 % of a 1024² atlas): union–find over shared edges
//! (vertex positions equal to 1e-9 of the scene's size), same plane (normals within 1e-6,
//! offsets within 1e-6 of the scene's size). Each chart is projected orthographically onto
//! its plane — axis `u` along the longest edge of its first polygon, `v = n × u` — so every
//! chart has the same texel size in world units: density is uniform by construction.
//!
//! **Packing.** Each chart's bounding rectangle, grown by `padding` texels on every side
//! (texels there are filled by dilation, so bilinear filtering never reads an empty one),
//! is placed by a guillotine allocator (the `guillotiere` crate; measured against `etagere`'s
//! shelf allocators, BENCHMARKS.md "Lightmaps": of 30 000 rectangles filling 90 % of the
//! square, guillotiere placed all in 0.19 s, etagere 37–39 %), tallest first. The texel
//! size is chosen so that the rectangles fill about 80 % of the texture, then grown by 5 %
//! until everything fits.

use std::collections::HashMap;

use glam::DVec3;

use crate::scene::Scene;
use crate::{Error, Result};

/// Texels of padding around every chart by default.
pub const DEFAULT_PADDING: usize = 2;

/// Lightmap side in texels by default.
pub const DEFAULT_SIZE: usize = 1024;

/// Share of the texture the charts' rectangles aim at when the texel size is automatic.
const TARGET_FILL: f64 = 0.8;

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

/// One chart: coplanar, edge-connected polygons (same side).
#[derive(Clone, Debug)]
pub struct Chart {
    /// Scene polygons.
    pub polygons: Vec<u32>,
    /// The world point at the chart's (u, v) minimum.
    pub origin: DVec3,
    /// Unit axes in the chart's plane.
    pub u: DVec3,
    /// Second axis, `n × u`.
    pub v: DVec3,
    /// Rectangle size in texels, padding included.
    pub width: usize,
    /// Rectangle height in texels, padding included.
    pub height: usize,
    /// Top-left texel of the rectangle in the atlas.
    pub x: usize,
    /// Top-left texel row.
    pub y: usize,
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
}

impl Atlas {
    /// Continuous texel coordinates (texel centres at +0.5) of the world point `p` on
    /// polygon `polygon`.
    #[inline]
    pub fn texel_coords(&self, polygon: u32, p: DVec3) -> (f64, f64) {
        let c = &self.charts[self.chart_of[polygon as usize] as usize];
        let d = p - c.origin;
        let pad = self.padding as f64;
        (c.x as f64 + pad + d.dot(c.u) / self.texel, c.y as f64 + pad + d.dot(c.v) / self.texel)
    }

    /// Normalised texture coordinates (glTF: origin at the image's top-left) of `p` on
    /// polygon `polygon`.
    #[inline]
    pub fn uv(&self, polygon: u32, p: DVec3) -> (f64, f64) {
        let (x, y) = self.texel_coords(polygon, p);
        (x / self.size as f64, y / self.size as f64)
    }

    /// The world point on chart `c`'s plane at continuous texel coordinates (x, y).
    #[inline]
    pub fn world(&self, c: usize, x: f64, y: f64) -> DVec3 {
        let ch = &self.charts[c];
        let pad = self.padding as f64;
        ch.origin + ch.u * ((x - ch.x as f64 - pad) * self.texel) + ch.v * ((y - ch.y as f64 - pad) * self.texel)
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
        let groups = charts(scene);
        // Each chart's frame and extent in world units.
        let mut frames = Vec::with_capacity(groups.len());
        for g in &groups {
            let first = &scene.polygons[g[0] as usize];
            let n = first.normal;
            let vs = &first.vertices;
            let mut u = DVec3::X;
            let mut best = -1.0;
            for k in 0..vs.len() {
                let e = vs[(k + 1) % vs.len()] - vs[k];
                if e.length_squared() > best {
                    best = e.length_squared();
                    u = e;
                }
            }
            let u = (u - n * n.dot(u)).normalize();
            let v = n.cross(u);
            let (mut lo, mut hi) = ((f64::INFINITY, f64::INFINITY), (f64::NEG_INFINITY, f64::NEG_INFINITY));
            for &p in g {
                for x in &scene.polygons[p as usize].vertices {
                    let (a, b) = (x.dot(u), x.dot(v));
                    lo = (lo.0.min(a), lo.1.min(b));
                    hi = (hi.0.max(a), hi.1.max(b));
                }
            }
            frames.push((u, v, lo, hi));
        }
        let pad = opts.padding;
        let n2 = (opts.size * opts.size) as f64;
        let rects = |texel: f64| -> Vec<(usize, usize)> {
            frames
                .iter()
                .map(|(_, _, lo, hi)| {
                    let w = (((hi.0 - lo.0) / texel).ceil() as usize).max(1) + 2 * pad;
                    let h = (((hi.1 - lo.1) / texel).ceil() as usize).max(1) + 2 * pad;
                    (w, h)
                })
                .collect()
        };
        let floor: f64 = (groups.len() * (1 + 2 * pad) * (1 + 2 * pad)) as f64;
        if floor > 0.95 * n2 {
            return Err(Error::Invalid(format!(
                "{} charts need at least {} texels with their padding, more than a {}² lightmap holds: \
                 raise --lightmap-size or bake vertex colours",
                groups.len(),
                floor,
                opts.size
            )));
        }
        let mut texel = match opts.texel {
            Some(t) => t,
            None => {
                let area: f64 = frames.iter().map(|(_, _, lo, hi)| (hi.0 - lo.0).max(0.0) * (hi.1 - lo.1).max(0.0)).sum();
                let mut t = (area.max(f64::MIN_POSITIVE) / (TARGET_FILL * n2)).sqrt();
                for _ in 0..30 {
                    let need: usize = rects(t).iter().map(|(w, h)| w * h).sum();
                    let ratio = need as f64 / (TARGET_FILL * n2);
                    if (ratio - 1.0).abs() < 0.01 {
                        break;
                    }
                    t *= ratio.sqrt();
                }
                t
            }
        };
        for _ in 0..60 {
            let r = rects(texel);
            if let Some(at) = pack(&r, opts.size) {
                let charts = groups
                    .iter()
                    .zip(&frames)
                    .zip(r.iter().zip(at))
                    .map(|((g, (u, v, lo, _)), ((w, h), (x, y)))| Chart {
                        polygons: g.clone(),
                        // The plane's point at (u, v) = lo: u, v and the normal are orthonormal.
                        origin: *u * lo.0 + *v * lo.1 + {
                            let p = &scene.polygons[g[0] as usize];
                            p.normal * p.normal.dot(p.vertices[0])
                        },
                        u: *u,
                        v: *v,
                        width: *w,
                        height: *h,
                        x,
                        y,
                    })
                    .collect::<Vec<_>>();
                let mut chart_of = vec![u32::MAX; scene.polygons.len()];
                for (c, ch) in charts.iter().enumerate() {
                    for &p in &ch.polygons {
                        chart_of[p as usize] = c as u32;
                    }
                }
                return Ok(Atlas { size: opts.size, texel, padding: pad, charts, chart_of });
            }
            if opts.texel.is_some() {
                return Err(Error::Invalid(format!(
                    "the charts at texel size {texel} do not fit a {}² lightmap: raise --lightmap-size or --texel-size",
                    opts.size
                )));
            }
            texel *= 1.05;
        }
        Err(Error::Invalid(format!("the charts do not fit a {}² lightmap: raise --lightmap-size", opts.size)))
    }
}

/// Places rectangles (tallest first) in a `size × size` square; their top-left corners in
/// input order, or None if one does not fit.
fn pack(rects: &[(usize, usize)], size: usize) -> Option<Vec<(usize, usize)>> {
    let mut order: Vec<usize> = (0..rects.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(rects[i].1), std::cmp::Reverse(rects[i].0)));
    let mut alloc = guillotiere::AtlasAllocator::new(guillotiere::size2(size as i32, size as i32));
    let mut at = vec![(0, 0); rects.len()];
    for i in order {
        let (w, h) = rects[i];
        if w > size || h > size {
            return None;
        }
        let a = alloc.allocate(guillotiere::size2(w as i32, h as i32))?;
        at[i] = (a.rectangle.min.x as usize, a.rectangle.min.y as usize);
    }
    Some(at)
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
