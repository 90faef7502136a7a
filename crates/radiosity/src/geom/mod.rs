//! Geometry shared by the pipeline's stages (scene, mesh, form factors, rendering): Newell
//! normals, Gauss–Legendre nodes, clipping of convex polygons by planes, 2-D convex set
//! differences (for shadows), small polygon helpers, and the point-to-polygon form-factor
//! kernel (`kernel`, crate-private; public as [`crate::form_factor::analytic::point_factor`]).
//! It depends on nothing else in the crate, so every stage may use it.
//!
//! Everything is f64; polygons are vertex lists in order (convex unless stated).

use std::sync::OnceLock;

use glam::{DVec2, DVec3};

pub(crate) mod kernel;

/// Largest Gauss–Legendre order kept in the table.
pub const MAX_GAUSS: usize = 32;

/// Gauss–Legendre nodes and weights of order `n` (1 ≤ n ≤ [`MAX_GAUSS`]) on [0, 1]: the
/// weights sum to 1 and the rule integrates polynomials of degree 2n − 1 exactly.
///
/// Nodes are the roots of the Legendre polynomial P_n found by Newton's method from
/// Tricomi's initial guesses; accurate to a few ulps.
pub fn gauss_legendre(n: usize) -> &'static [(f64, f64)] {
    static TABLE: OnceLock<Vec<Vec<(f64, f64)>>> = OnceLock::new();
    let t = TABLE.get_or_init(|| (0..=MAX_GAUSS).map(gl_nodes).collect());
    &t[n.clamp(1, MAX_GAUSS)]
}

fn gl_nodes(n: usize) -> Vec<(f64, f64)> {
    if n == 0 {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(n);
    for k in 1..=n {
        let mut x = (std::f64::consts::PI * (k as f64 - 0.25) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_{n-1}(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0f64, x);
            for j in 2..=n {
                let p2 = ((2 * j - 1) as f64 * x * p1 - (j - 1) as f64 * p0) / j as f64;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 1 { x } else { p1 };
            let pm = if n == 1 { 1.0 } else { p0 };
            dp = n as f64 * (x * pn - pm) / (x * x - 1.0);
            let dx = pn / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (1.0 + x), 0.5 * w));
    }
    out.reverse();
    out
}

/// Clips the convex polygon `poly` to the half-space `dist(p) >= 0` (`dist` affine, e.g. a
/// signed plane distance), appending the result to `out` (cleared first). Vertices with
/// `|dist| <= eps` count as on the plane and are kept.
pub fn clip_halfspace(poly: &[DVec3], dist: impl Fn(DVec3) -> f64, eps: f64, out: &mut Vec<DVec3>) {
    out.clear();
    clip_append(poly, |p| snap(dist(p), eps), out);
}

/// One Sutherland–Hodgman step: appends to `out` the part of the convex polygon `poly`
/// where `d >= 0` (`d` already snapped to 0 on the boundary); returns how many vertices it
/// appended, or 0 (and appends nothing) when fewer than 3 remain.
#[inline]
fn clip_append<T>(poly: &[T], d: impl Fn(T) -> f64, out: &mut Vec<T>) -> usize
where
    T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T> + std::ops::Mul<f64, Output = T>,
{
    let start = out.len();
    let Some(&last) = poly.last() else { return 0 };
    let (mut prev, mut dprev) = (last, d(last));
    for &cur in poly {
        let dcur = d(cur);
        if (dprev > 0.0 && dcur < 0.0) || (dprev < 0.0 && dcur > 0.0) {
            let t = dprev / (dprev - dcur);
            out.push(prev + (cur - prev) * t);
        }
        if dcur >= 0.0 {
            out.push(cur);
        }
        prev = cur;
        dprev = dcur;
    }
    let n = out.len() - start;
    if n < 3 {
        out.truncate(start);
        0
    } else {
        n
    }
}

/// Splits a convex 2-D polygon by the signed distance `d` of its points: the part where
/// `d ≤ 0` is appended to `outside`, the part where `d ≥ 0` to `inside`, each as
/// [`clip_append`] would append it with `−d` and `d` (the same points, bit for bit: the
/// crossing `t = d₀ / (d₀ − d₁)` is unchanged by negating both). Returns how many points
/// each got (0 for a part under 3 points, which is not appended).
fn split_append(poly: &[DVec2], d: impl Fn(DVec2) -> f64, outside: &mut Vec<DVec2>, inside: &mut Vec<DVec2>) -> (usize, usize) {
    let (so, si) = (outside.len(), inside.len());
    let Some(&last) = poly.last() else { return (0, 0) };
    let (mut prev, mut dprev) = (last, d(last));
    for &cur in poly {
        let dcur = d(cur);
        if (dprev > 0.0 && dcur < 0.0) || (dprev < 0.0 && dcur > 0.0) {
            let t = dprev / (dprev - dcur);
            let x = prev + (cur - prev) * t;
            outside.push(x);
            inside.push(x);
        }
        if dcur <= 0.0 {
            outside.push(cur);
        }
        if dcur >= 0.0 {
            inside.push(cur);
        }
        prev = cur;
        dprev = dcur;
    }
    let keep = |v: &mut Vec<DVec2>, start: usize| {
        let n = v.len() - start;
        if n < 3 {
            v.truncate(start);
            0
        } else {
            n
        }
    };
    (keep(outside, so), keep(inside, si))
}

#[inline]
fn snap(d: f64, eps: f64) -> f64 {
    if d.abs() <= eps {
        0.0
    } else {
        d
    }
}

/// Twice the signed area of a 2-D polygon (positive when counter-clockwise).
pub fn area2_2d(p: &[DVec2]) -> f64 {
    let m = p.len();
    let mut a = 0.0;
    for k in 0..m {
        a += p[k].perp_dot(p[(k + 1) % m]);
    }
    a
}

/// Area of a planar 3-D polygon.
pub fn area_3d(p: &[DVec3]) -> f64 {
    0.5 * newell_normal(p).length()
}

/// Clips a convex 2-D polygon to the left of the directed line `a → b` (`side = 1`) or to
/// its right (`side = -1`), appending to `out` (not cleared).
fn clip_line_2d(poly: &[DVec2], a: DVec2, b: DVec2, side: f64, eps: f64, out: &mut Vec<DVec2>) -> usize {
    let e = b - a;
    let len = e.length();
    clip_append(poly, |p| snap(side * e.perp_dot(p - a) / len, eps), out)
}

/// A set of disjoint convex 2-D polygons stored flat (one buffer, ranges).
#[derive(Clone, Debug, Default)]
pub struct PieceSet {
    pts: Vec<DVec2>,
    ranges: Vec<(u32, u32)>,
}

impl PieceSet {
    /// Empties the set.
    pub fn clear(&mut self) {
        self.pts.clear();
        self.ranges.clear();
    }
    /// Adds one convex piece.
    pub fn push(&mut self, p: &[DVec2]) {
        let s = self.pts.len() as u32;
        self.pts.extend_from_slice(p);
        self.ranges.push((s, self.pts.len() as u32));
    }
    /// Number of pieces.
    pub fn len(&self) -> usize {
        self.ranges.len()
    }
    /// True if there are no pieces.
    pub fn is_empty(&self) -> bool {
        self.ranges.is_empty()
    }
    /// Piece `k`.
    pub fn piece(&self, k: usize) -> &[DVec2] {
        let (a, b) = self.ranges[k];
        &self.pts[a as usize..b as usize]
    }
    /// Axis-aligned bounds of all pieces.
    pub fn bounds(&self) -> (DVec2, DVec2) {
        bounds_2d(&self.pts)
    }
    /// Total area.
    pub fn area(&self) -> f64 {
        (0..self.len()).map(|k| 0.5 * area2_2d(self.piece(k)).abs()).sum()
    }

    /// `self \ cutter` into `out` (cleared), for a counter-clockwise convex `cutter`.
    /// Each piece is cut by the cutter's edge lines: the part outside an edge is kept, the
    /// rest goes on to the next edge, and what is left inside all edges is dropped. Pieces
    /// whose area is below `min_area` are dropped too (slivers from rounding).
    pub fn subtract(&self, cutter: &[DVec2], eps: f64, min_area: f64, out: &mut PieceSet, tmp: &mut [Vec<DVec2>; 2]) {
        out.clear();
        let (clo, chi) = bounds_2d(cutter);
        let m = cutter.len();
        let [cur, next] = tmp;
        for k in 0..self.len() {
            let p = self.piece(k);
            let (plo, phi) = bounds_2d(p);
            if plo.x >= chi.x - eps || plo.y >= chi.y - eps || phi.x <= clo.x + eps || phi.y <= clo.y + eps {
                out.push(p);
                continue;
            }
            cur.clear();
            cur.extend_from_slice(p);
            for e in 0..m {
                let (a, b) = (cutter[e], cutter[(e + 1) % m]);
                let ed = b - a;
                if ed.length_squared() == 0.0 {
                    continue;
                }
                let len = ed.length();
                // The part outside this edge (right of a→b) is outside the cutter: kept.
                // The inside part goes on to the next edge. Both from one pass over the
                // piece (the same points as clipping it twice, once to each side).
                let s = out.pts.len();
                next.clear();
                let (n_out, n_in) = split_append(cur, |q| snap(ed.perp_dot(q - a) / len, eps), &mut out.pts, next);
                if n_out > 0 {
                    if 0.5 * area2_2d(&out.pts[s..]).abs() > min_area {
                        out.ranges.push((s as u32, out.pts.len() as u32));
                    } else {
                        out.pts.truncate(s);
                    }
                }
                std::mem::swap(cur, next);
                if n_in == 0 {
                    break;
                }
            }
        }
    }
}

impl PieceSet {
    /// Cuts every piece by the line through `a` and `b` (both sides kept), into `out`
    /// (cleared). Pieces below `min_area` are dropped.
    pub fn split(&self, a: DVec2, b: DVec2, eps: f64, min_area: f64, out: &mut PieceSet) {
        out.clear();
        if (b - a).length_squared() == 0.0 {
            for k in 0..self.len() {
                out.push(self.piece(k));
            }
            return;
        }
        for k in 0..self.len() {
            let p = self.piece(k);
            for side in [1.0, -1.0] {
                let s = out.pts.len();
                if clip_line_2d(p, a, b, side, eps, &mut out.pts) > 0 {
                    if 0.5 * area2_2d(&out.pts[s..]).abs() > min_area {
                        out.ranges.push((s as u32, out.pts.len() as u32));
                    } else {
                        out.pts.truncate(s);
                    }
                }
            }
        }
    }
}

/// Axis-aligned bounds of 2-D points.
pub fn bounds_2d(p: &[DVec2]) -> (DVec2, DVec2) {
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for &q in p {
        lo = lo.min(q);
        hi = hi.max(q);
    }
    (lo, hi)
}

/// Axis-aligned bounds of 3-D points.
pub fn bounds_3d(p: &[DVec3]) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for &q in p {
        lo = lo.min(q);
        hi = hi.max(q);
    }
    (lo, hi)
}

/// Shortest distance between the segments `p0p1` and `q0q1` (Ericson 2005, §5.1.9).
pub fn segment_distance(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> f64 {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.length_squared();
    let e = d2.length_squared();
    let f = d2.dot(r);
    let (s, t);
    if a <= 0.0 && e <= 0.0 {
        return r.length();
    }
    if a <= 0.0 {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(r);
        if e <= 0.0 {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > 0.0 { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    ((p0 + d1 * s) - (q0 + d2 * t)).length()
}

/// An orthonormal frame of a plane: origin, two in-plane axes and the normal
/// (`e1 × e2 = n`), for 2-D work on a polygon.
#[derive(Clone, Copy, Debug)]
pub struct PlaneFrame {
    /// A point of the plane.
    pub origin: DVec3,
    /// First in-plane axis.
    pub e1: DVec3,
    /// Second in-plane axis.
    pub e2: DVec3,
    /// Unit normal.
    pub n: DVec3,
}

impl PlaneFrame {
    /// The frame of the plane through `origin` with unit normal `n`.
    pub fn new(origin: DVec3, n: DVec3) -> Self {
        let (e1, e2) = crate::sampling::basis(n);
        PlaneFrame { origin, e1, e2, n }
    }
    /// In-plane coordinates of `p`.
    #[inline]
    pub fn to_2d(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.e1), d.dot(self.e2))
    }
    /// The point of the plane with coordinates `q`.
    #[inline]
    pub fn to_3d(&self, q: DVec2) -> DVec3 {
        self.origin + self.e1 * q.x + self.e2 * q.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        for n in 1..=MAX_GAUSS {
            let r = gauss_legendre(n);
            assert_eq!(r.len(), n);
            let wsum: f64 = r.iter().map(|p| p.1).sum();
            assert!((wsum - 1.0).abs() < 1e-14, "n={n} {wsum}");
            let deg = 2 * n - 1;
            let q: f64 = r.iter().map(|&(x, w)| w * x.powi(deg as i32)).sum();
            assert!((q - 1.0 / (deg as f64 + 1.0)).abs() < 1e-14, "n={n}");
        }
    }

    #[test]
    fn subtracting_a_square_hole_leaves_the_frame() {
        let mut s = PieceSet::default();
        let sq = |a: f64, b: f64| vec![DVec2::new(a, a), DVec2::new(b, a), DVec2::new(b, b), DVec2::new(a, b)];
        s.push(&sq(0.0, 4.0));
        let mut out = PieceSet::default();
        let mut tmp = [Vec::new(), Vec::new()];
        s.subtract(&sq(1.0, 2.0), 1e-12, 0.0, &mut out, &mut tmp);
        assert!((out.area() - 15.0).abs() < 1e-12, "{}", out.area());
        // A cutter covering everything leaves nothing; a disjoint one leaves all.
        s.subtract(&sq(-1.0, 5.0), 1e-12, 0.0, &mut out, &mut tmp);
        assert!(out.is_empty());
        s.subtract(&sq(5.0, 6.0), 1e-12, 0.0, &mut out, &mut tmp);
        assert!((out.area() - 16.0).abs() < 1e-12);
    }

    #[test]
    fn subtracting_a_cutter_twice_removes_nothing_more() {
        // Pseudo-random convex cutters (triangles and quads) over a unit square.
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let sq = vec![DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(1.0, 1.0), DVec2::new(0.0, 1.0)];
        let mut tmp = [Vec::new(), Vec::new()];
        let mut worst: f64 = 0.0;
        for _ in 0..200 {
            let mut set = PieceSet::default();
            set.push(&sq);
            let mut cutters = Vec::new();
            for _ in 0..6 {
                let c = DVec2::new(rnd() * 1.4 - 0.2, rnd() * 1.4 - 0.2);
                let r = 0.05 + 0.4 * rnd();
                let n = 3 + (rnd() * 2.0) as usize;
                let a0 = rnd() * 6.28;
                let mut poly: Vec<DVec2> = (0..n).map(|k| c + r * DVec2::from_angle(a0 + k as f64 * std::f64::consts::TAU / n as f64)).collect();
                if area2_2d(&poly) < 0.0 {
                    poly.reverse();
                }
                cutters.push(poly);
            }
            let mut once = set.clone();
            let mut next = PieceSet::default();
            for c in &cutters {
                once.subtract(c, 1e-12, 1e-14, &mut next, &mut tmp);
                std::mem::swap(&mut once, &mut next);
            }
            let mut twice = set.clone();
            for c in &cutters {
                for _ in 0..2 {
                    twice.subtract(c, 1e-12, 1e-14, &mut next, &mut tmp);
                    std::mem::swap(&mut twice, &mut next);
                }
            }
            worst = worst.max((once.area() - twice.area()).abs());
        }
        assert!(worst < 1e-12, "{worst}");
    }

    #[test]
    fn segment_distance_cases() {
        let d = segment_distance(DVec3::ZERO, DVec3::X, DVec3::new(0.5, 1.0, 1.0), DVec3::new(0.5, 1.0, 2.0));
        assert!((d - 2f64.sqrt()).abs() < 1e-15);
        let d = segment_distance(DVec3::ZERO, DVec3::X, DVec3::X, DVec3::new(1.0, 1.0, 0.0));
        assert_eq!(d, 0.0);
    }
}

/// Newell's normal (not normalised; length = 2·area for a planar polygon).
pub fn newell_normal(v: &[DVec3]) -> DVec3 {
    let mut n = DVec3::ZERO;
    let c = v[0];
    for i in 1..v.len().saturating_sub(1) {
        n += (v[i] - c).cross(v[i + 1] - c);
    }
    n
}

/// True when `x` (on the plane of the convex polygon `v` with normal `n`) lies strictly
/// inside it, more than `eps` from every edge.
pub fn inside_convex(x: DVec3, v: &[DVec3], n: DVec3, eps: f64) -> bool {
    (0..v.len()).all(|k| {
        let e = v[(k + 1) % v.len()] - v[k];
        let l = e.length();
        l > 0.0 && e.cross(x - v[k]).dot(n) > eps * l
    })
}
