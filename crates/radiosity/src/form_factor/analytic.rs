//! Exact, unoccluded polygon-to-polygon form factors by the double contour integral.
//!
//! ```text
//! A_i F_ij = 1/(2π) ∮_{∂A_i} ∮_{∂A_j} ln r  dx_i · dx_j
//! ```
//!
//! (Stokes' theorem applied twice to the area integral; Sparrow 1963, Schröder & Hanrahan
//! 1993 "On the form factor between two polygons", who give the closed form with complex
//! dilogarithms.) We evaluate the same integral edge pair by edge pair, without complex
//! arithmetic:
//!
//! - for two edges `p(s) = a + s·u`, `q(t) = b + t·v` the inner integral over `t` is
//!   elementary: with `τ = (p(s) − b)·v` and `h` the distance of `p(s)` from the line of
//!   `q`, `∫₀^L ln r dt = G(L − τ) − G(−τ)`, `G(z) = ½ z ln(z² + h²) − z + h atan(z/h)`;
//! - parallel (and collinear, i.e. shared) edges have a closed form for the outer integral
//!   too: `H(z) = ¼ (z² − h²) ln(z² + h²) − ¾ z² + h z atan(z/h)`;
//! - otherwise the outer integral over `s` uses Gauss–Legendre panels whose length is at
//!   most the panel's distance from the other edge, with the number of points chosen from
//!   that ratio (Bernstein-ellipse bound) for ~1e-16 relative accuracy. Edges that touch
//!   (shared vertices) get geometrically graded panels toward the touching point;
//! - perpendicular edges contribute nothing (`dx_i · dx_j = 0`).
//!
//! The formula needs every point of each polygon in front of the other; the front-side
//! conditions factor (`cos θ_i > 0` depends only on the point of `j`, `cos θ_j > 0` only on
//! the point of `i`), so each polygon is first clipped to the front half-space of the
//! other — exact, and it makes coplanar pairs (F = 0) and pairs behind each other exact
//! too. Coordinates are translated and scaled to O(1) first: the `ln(scale)` part of the
//! integrand cancels over closed contours, which keeps far pairs well conditioned.
//!
//! **Unoccluded by definition**: the result ignores anything between the polygons. For a
//! scene that is not convex (some polygon in front of another's plane on both sides, so
//! that something could block), [`super::compute`] still runs it (it is the exact answer
//! the occluded methods are compared with) but adds a warning to the statistics.

use glam::DVec3;

use super::geom::{clip_halfspace, gauss_legendre, segment_distance};

/// `A_i · F_ij` for the convex planar polygons `pi` (front normal `ni`) and `pj` (`nj`),
/// counting only the front sides (vertex order, right-hand rule). No occlusion.
pub fn area_factor(pi: &[DVec3], ni: DVec3, pj: &[DVec3], nj: DVec3) -> f64 {
    let mut s = Scratch::default();
    area_factor_with(&mut s, pi, ni, pj, nj)
}

/// Form factor from the differential area at `x` (unit normal `n`) to the convex planar
/// polygon `poly`, front side only (right-hand rule about `poly_normal`; zero when `x` is
/// behind it), no occlusion: Lambert's contour integral
/// `F = 1/(2π) Σ_edges γ_k (n · (r_k × r_{k+1}) / |r_k × r_{k+1}|)` with `γ_k` the angle each
/// edge subtends at `x` (Baum, Rushmeier & Winget 1989; the point-sampled method's kernel).
pub fn point_factor(x: DVec3, n: DVec3, poly: &[DVec3], poly_normal: DVec3) -> f64 {
    crate::geom::kernel::point_to_polygon(x, n, poly, poly_normal)
}

/// `F_ij = area_factor / A_i` (see [`area_factor`]).
pub fn form_factor(pi: &[DVec3], ni: DVec3, pj: &[DVec3], nj: DVec3) -> f64 {
    let a = super::geom::area_3d(pi);
    if a > 0.0 {
        area_factor(pi, ni, pj, nj) / a
    } else {
        0.0
    }
}

/// Reusable buffers for [`area_factor_with`].
#[derive(Default, Debug, Clone)]
pub struct Scratch {
    a: Vec<DVec3>,
    b: Vec<DVec3>,
    ca: Vec<DVec3>,
    cb: Vec<DVec3>,
}

/// [`area_factor`] with caller-owned buffers (no allocation once they have grown).
pub fn area_factor_with(s: &mut Scratch, pi: &[DVec3], ni: DVec3, pj: &[DVec3], nj: DVec3) -> f64 {
    if pi.len() < 3 || pj.len() < 3 {
        return 0.0;
    }
    // Local, scaled coordinates: origin at pi[0], largest distance from it = 1.
    let o = pi[0];
    let mut scale: f64 = 0.0;
    for v in pi.iter().chain(pj) {
        scale = scale.max((*v - o).length());
    }
    if !(scale > 0.0) || !scale.is_finite() {
        return 0.0;
    }
    let inv = 1.0 / scale;
    s.a.clear();
    s.a.extend(pi.iter().map(|v| (*v - o) * inv));
    s.b.clear();
    s.b.extend(pj.iter().map(|v| (*v - o) * inv));
    const EPS: f64 = 1e-12;
    let (a0, b0) = (s.a[0], s.b[0]);
    // Each polygon clipped to the front half-space of the other.
    clip_halfspace(&s.a, |p| nj.dot(p - b0), EPS, &mut s.ca);
    clip_halfspace(&s.b, |p| ni.dot(p - a0), EPS, &mut s.cb);
    if s.ca.is_empty() || s.cb.is_empty() {
        return 0.0;
    }
    // Nothing strictly in front (coplanar, or touching only along the plane): F = 0.
    if !s.ca.iter().any(|p| nj.dot(*p - b0) > EPS) || !s.cb.iter().any(|p| ni.dot(*p - a0) > EPS) {
        return 0.0;
    }
    let (ca, cb) = (&s.ca, &s.cb);
    let mut sum = 0.0;
    for k in 0..ca.len() {
        let (p0, p1) = (ca[k], ca[(k + 1) % ca.len()]);
        for l in 0..cb.len() {
            let (q0, q1) = (cb[l], cb[(l + 1) % cb.len()]);
            sum += edge_pair(p0, p1, q0, q1);
        }
    }
    // Both contours counter-clockwise about their own front normals.
    sum / (2.0 * std::f64::consts::PI) * scale * scale
}

/// `(u·v) ∫₀^{La} ∫₀^{Lb} ln |p(s) − q(t)| dt ds` for the edges `p0p1` and `q0q1`.
fn edge_pair(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> f64 {
    let ea = p1 - p0;
    let eb = q1 - q0;
    let (la, lb) = (ea.length(), eb.length());
    if !(la > 0.0 && lb > 0.0) {
        return 0.0;
    }
    let (u, v) = (ea / la, eb / lb);
    let c = u.dot(v);
    if c.abs() < 1e-15 {
        return 0.0;
    }
    if u.cross(v).length() < 1e-12 {
        // Parallel (collinear when h = 0): closed form in both variables.
        let w = q0 - p0;
        let cpos = w.dot(u);
        let h = (w - u * cpos).length();
        let sig = c.signum();
        let val = hfun(la - cpos, h) - hfun(-cpos, h) - hfun(la - cpos - sig * lb, h) + hfun(-cpos - sig * lb, h);
        return c * sig * val;
    }
    c * outer_integral(p0, u, la, q0, v, lb)
}

/// `∫₀^{La} I(s) ds` with `I(s) = ∫₀^{Lb} ln |p0 + s·u − q0 − t·v| dt` in closed form.
fn outer_integral(p0: DVec3, u: DVec3, la: f64, q0: DVec3, v: DVec3, lb: f64) -> f64 {
    let q1 = q0 + v * lb;
    let inner = |s: f64| {
        let w = p0 + u * s - q0;
        let tau = w.dot(v);
        let h = w.cross(v).length();
        gfun(lb - tau, h) - gfun(-tau, h)
    };
    const MAX_DEPTH: u32 = 60;
    const MAX_PANELS: usize = 4000;
    let mut stack = [(0.0f64, 0.0f64, 0u32); 2 * MAX_DEPTH as usize + 4];
    let mut sp = 1;
    stack[0] = (0.0, la, 0);
    let mut total = 0.0;
    let mut panels = 0usize;
    while sp > 0 {
        sp -= 1;
        let (s0, s1, depth) = stack[sp];
        let len = s1 - s0;
        if !(len > 0.0) {
            continue;
        }
        let d = segment_distance(p0 + u * s0, p0 + u * s1, q0, q1);
        let n = match points_needed(len, d) {
            Some(n) => n,
            None if depth >= MAX_DEPTH || panels >= MAX_PANELS => 16,
            None => {
                let mid = 0.5 * (s0 + s1);
                stack[sp] = (s0, mid, depth + 1);
                stack[sp + 1] = (mid, s1, depth + 1);
                sp += 2;
                continue;
            }
        };
        panels += 1;
        let mut acc = 0.0;
        for &(x, w) in gauss_legendre(n) {
            acc += w * inner(s0 + len * x);
        }
        total += acc * len;
    }
    total
}

/// Gauss–Legendre points for ~1e-16 relative error on a panel of length `len` whose
/// nearest singularity is `dist` away, or None when the panel must be split. The bound
/// puts the singularity beside the panel's middle (the worst place): Bernstein ellipse
/// ρ = 2r + √(4r² + 1), r = dist/len, error ~ ρ^(−2n).
#[inline]
fn points_needed(len: f64, dist: f64) -> Option<usize> {
    let r = dist / len;
    if !(r >= 1.0) {
        return None;
    }
    let rho = 2.0 * r + (4.0 * r * r + 1.0).sqrt();
    let n = (37.0 / (2.0 * rho.ln())).ceil() as usize;
    Some(n.clamp(3, 16))
}

/// `G(z) = ∫ ½ ln(z² + h²) dz = ½ z ln(z² + h²) − z + h atan(z/h)`.
#[inline]
fn gfun(z: f64, h: f64) -> f64 {
    let q = z * z + h * h;
    let l = if q > 0.0 { 0.5 * z * q.ln() } else { 0.0 };
    let at = if h > 0.0 { h * (z / h).atan() } else { 0.0 };
    l - z + at
}

/// `H(z) = ∫ G dz = ¼ (z² − h²) ln(z² + h²) − ¾ z² + h z atan(z/h)`.
#[inline]
fn hfun(z: f64, h: f64) -> f64 {
    let q = z * z + h * h;
    let l = if q > 0.0 { 0.25 * (z * z - h * h) * q.ln() } else { 0.0 };
    let at = if h > 0.0 { h * z * (z / h).atan() } else { 0.0 };
    l - 0.75 * z * z + at
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::kernel::point_to_polygon;

    fn v(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    /// Howell C-11: directly opposed a × b rectangles at distance c.
    fn parallel_exact(a: f64, b: f64, c: f64) -> f64 {
        let (x, y) = (a / c, b / c);
        let (x2, y2) = (x * x, y * y);
        2.0 / (std::f64::consts::PI * x * y)
            * ((((1.0 + x2) * (1.0 + y2)) / (1.0 + x2 + y2)).sqrt().ln()
                + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
                + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
                - x * x.atan()
                - y * y.atan())
    }

    #[test]
    fn unit_cube_faces() {
        let bottom = [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)];
        let top = [v(0., 0., 1.), v(0., 1., 1.), v(1., 1., 1.), v(1., 0., 1.)];
        let side = [v(0., 0., 0.), v(0., 0., 1.), v(1., 0., 1.), v(1., 0., 0.)]; // y = 0, normal +y
        let f = form_factor(&bottom, DVec3::Z, &top, -DVec3::Z);
        assert!((f - parallel_exact(1., 1., 1.)).abs() < 1e-14, "{f}");
        let g = form_factor(&bottom, DVec3::Z, &side, DVec3::Y);
        assert!((g - 0.200043776).abs() < 5e-10, "{g}");
        // Back sides and coplanar pairs.
        assert_eq!(form_factor(&bottom, DVec3::Z, &top, DVec3::Z), 0.0);
        let next = [v(1., 0., 0.), v(2., 0., 0.), v(2., 1., 0.), v(1., 1., 0.)];
        assert_eq!(form_factor(&bottom, DVec3::Z, &next, DVec3::Z), 0.0);
    }

    #[test]
    fn general_position_matches_gauss_cubature_of_the_point_kernel() {
        // Two triangles in general position, far enough apart that a high-order tensor
        // Gauss rule over the sender converges to machine precision.
        let a = [v(0.1, 0.0, 0.2), v(1.0, 0.3, 0.0), v(0.2, 0.9, 0.1)];
        let na = crate::scene::newell_normal(&a).normalize();
        let b = [v(0.3, 0.2, 2.0), v(0.4, 1.4, 2.3), v(1.5, 0.5, 1.9)];
        let nb = crate::scene::newell_normal(&b).normalize();
        let (b, nb) = if nb.dot(na) > 0.0 { ([b[0], b[2], b[1]], -nb) } else { (b, nb) };
        let exact = area_factor(&a, na, &b, nb);
        let gl = gauss_legendre(24);
        let mut sum = 0.0;
        for &(x, wx) in gl {
            for &(y, wy) in gl {
                // Collapsed coordinates on the triangle: Jacobian 2A·x.
                let p = a[0] + (a[1] - a[0]) * x + (a[2] - a[1]) * (x * y);
                sum += wx * wy * x * point_to_polygon(p, na, &b, nb);
            }
        }
        let area = crate::geom::area_3d(&a);
        let quad = sum * 2.0 * area;
        assert!(exact > 0.0);
        assert!((exact - quad).abs() < 1e-12 * exact, "{exact} vs {quad}");
    }

    #[test]
    fn touching_triangles_add_up_to_their_quads() {
        // Perpendicular rectangles sharing an edge, each cut along a diagonal: the four
        // triangle pairs include non-parallel edges that touch at shared vertices (the
        // graded-panel path); their sum must equal the rectangles' closed form.
        let r1 = [v(0., 0., 0.), v(1., 0., 0.), v(1., 2., 0.), v(0., 2., 0.)]; // z = 0, +z
        let r2 = [v(0., 0., 0.), v(0., 2., 0.), v(0., 2., 1.5), v(0., 0., 1.5)]; // x = 0, +x
        let (n1, n2) = (DVec3::Z, DVec3::X);
        let whole = area_factor(&r1, n1, &r2, n2);
        let t1 = [[r1[0], r1[1], r1[2]], [r1[0], r1[2], r1[3]]];
        let t2 = [[r2[0], r2[1], r2[2]], [r2[0], r2[2], r2[3]]];
        let mut sum = 0.0;
        for a in &t1 {
            for b in &t2 {
                sum += area_factor(a, n1, b, n2);
            }
        }
        assert!((whole - sum).abs() < 1e-12 * whole, "{whole} vs {sum}");
        // Reciprocity.
        let back = area_factor(&r2, n2, &r1, n1);
        assert!((whole - back).abs() < 1e-14 * whole);
    }
}
