//! The point-to-polygon form factor by Lambert's contour integral.
//!
//! For a differential area at `x` with unit normal `n` and a polygon with vertices
//! `p_1 … p_m` entirely above the tangent plane of `x`:
//!
//! ```text
//! F(dA_x → A) = 1/(2π) · Σ_k  n · Γ_k,   Γ_k = θ_k · (R_k × R_{k+1}) / |R_k × R_{k+1}|
//! ```
//!
//! with `R_k = p_k − x` and `θ_k` the angle between `R_k` and `R_{k+1}` (Lambert 1760;
//! Hottel & Sarofim 1967; used for radiosity by Baum, Rushmeier & Winget 1989). Parts of
//! the polygon below the horizon of `x` are clipped away first (Sutherland–Hodgman), which
//! makes the formula exact for any convex polygon in any position. Computed in f64.

use glam::DVec3;

/// Polygons with fewer vertices than this are clipped in stack buffers; larger ones (the
/// 256-gon disks of the tests, shadow pieces) use the heap.
const MAXV: usize = 16;

/// Form factor from the differential area at `x` (unit normal `n`) to the convex polygon
/// `poly`, counting only the polygon's front side (right-hand rule about `poly_normal`):
/// zero if `x` is not in front of the polygon. No occlusion.
#[inline]
pub fn point_to_polygon(x: DVec3, n: DVec3, poly: &[DVec3], poly_normal: DVec3) -> f64 {
    if poly_normal.dot(x - poly[0]) <= 0.0 {
        return 0.0;
    }
    point_to_polygon_unsided(x, n, poly)
}

/// The far-field (point-to-point) approximation of the factor from `dA_x` (normal `n`) to a
/// small element of area `area` at `y` (normal `ny`): `cosθ_x cosθ_y A / (π r²)`. Its
/// relative error is O((size/r)²); callers renormalise sums of it against
/// [`point_to_polygon`] on the whole patch.
#[inline]
pub fn point_to_point(x: DVec3, n: DVec3, y: DVec3, ny: DVec3, area: f64) -> f64 {
    let d = y - x;
    let r2 = d.length_squared();
    let cx = n.dot(d);
    let cy = -ny.dot(d);
    if cx <= 0.0 || cy <= 0.0 || r2 <= 0.0 {
        return 0.0;
    }
    cx * cy * area / (std::f64::consts::PI * r2 * r2)
}

/// As [`point_to_polygon`] without the front-side test.
pub fn point_to_polygon_unsided(x: DVec3, n: DVec3, poly: &[DVec3]) -> f64 {
    // Heights over the tangent plane of x; the polygon is clipped to n·R >= 0 only when it
    // crosses it (most calls: no clipping, no buffers).
    let mut any_above = false;
    let mut all_above = true;
    for p in poly {
        if n.dot(*p - x) > 0.0 {
            any_above = true;
        } else {
            all_above = false;
        }
    }
    if !any_above {
        return 0.0;
    }
    if all_above {
        return contour_sum(n, poly.len(), |k| poly[k] - x);
    }
    if poly.len() < MAXV {
        let mut buf = [DVec3::ZERO; MAXV];
        clipped(x, n, poly, &mut buf)
    } else {
        let mut buf = vec![DVec3::ZERO; poly.len() + 1];
        clipped(x, n, poly, &mut buf)
    }
}

/// The contour sum of the part of `poly` above the tangent plane of `x` (Sutherland–Hodgman
/// against n·R > 0); `buf` holds `poly.len() + 1` points.
fn clipped(x: DVec3, n: DVec3, poly: &[DVec3], buf: &mut [DVec3]) -> f64 {
    let len = poly.len();
    let mut m = 0;
    for k in 0..len {
        let (a, b) = (poly[k] - x, poly[(k + 1) % len] - x);
        let (ha, hb) = (n.dot(a), n.dot(b));
        if ha > 0.0 {
            buf[m] = a;
            m += 1;
        }
        if (ha > 0.0) != (hb > 0.0) {
            let t = ha / (ha - hb);
            // Project exactly onto the plane to avoid tiny negative heights.
            let p = a + (b - a) * t;
            buf[m] = p - n * n.dot(p);
            m += 1;
        }
    }
    if m < 3 {
        return 0.0;
    }
    contour_sum(n, m, |k| buf[k])
}

/// `1/(2π) |Σ_k n·Γ_k|` over the closed contour of the `m` points `rel(k)` (positions
/// relative to x, all on or above its tangent plane).
#[inline]
fn contour_sum(n: DVec3, m: usize, rel: impl Fn(usize) -> DVec3) -> f64 {
    let mut sum = 0.0;
    let mut a = rel(m - 1);
    for k in 0..m {
        let b = rel(k);
        let c = a.cross(b);
        let s = c.length();
        if s > 0.0 {
            let theta = s.atan2(a.dot(b));
            sum += n.dot(c) * (theta / s);
        }
        a = b;
    }
    (sum.abs() / (2.0 * std::f64::consts::PI)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_under_centre_of_large_square_approaches_one() {
        let s = 1e4;
        let poly = [DVec3::new(-s, -s, 1.0), DVec3::new(-s, s, 1.0), DVec3::new(s, s, 1.0), DVec3::new(s, -s, 1.0)];
        let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &poly, -DVec3::Z);
        assert!((f - 1.0).abs() < 1e-3, "{f}");
    }

    #[test]
    fn point_to_parallel_square_matches_closed_form() {
        // Differential area facing a coaxial parallel square of side 2a at distance c:
        // F = (2/π) [ A/√(1+A²) atan(A/√(1+A²)) ] with A = a/c ... use the rectangle corner
        // formula: for a corner-aligned rectangle a × b at distance c,
        // F = 1/(2π) [ X/√(1+X²) atan(Y/√(1+X²)) + Y/√(1+Y²) atan(X/√(1+Y²)) ], X=a/c, Y=b/c.
        let (a, b, c): (f64, f64, f64) = (0.7, 1.3, 0.9);
        let (x, y) = (a / c, b / c);
        let exact = 1.0 / (2.0 * std::f64::consts::PI)
            * (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
                + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan());
        let poly = [DVec3::new(0., 0., c), DVec3::new(0., b, c), DVec3::new(a, b, c), DVec3::new(a, 0., c)];
        let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &poly, -DVec3::Z);
        assert!((f - exact).abs() < 1e-14, "{f} vs {exact}");
        // Back side and reversed vertex order.
        assert_eq!(point_to_polygon(DVec3::ZERO, DVec3::Z, &poly, DVec3::Z), 0.0);
    }

    #[test]
    fn clipping_below_horizon_halves_a_symmetric_polygon() {
        // A square standing on the tangent plane's horizon line, centred: half is below.
        let poly = [DVec3::new(-1., -1., 2.), DVec3::new(1., -1., 2.), DVec3::new(1., 1., 2.), DVec3::new(-1., 1., 2.)];
        let full = point_to_polygon_unsided(DVec3::ZERO, DVec3::Z, &poly);
        let tilted = point_to_polygon_unsided(DVec3::ZERO, DVec3::Y, &poly);
        assert!(full > 0.0 && tilted > 0.0 && tilted < full);
        // The closed unit cube seen from a point on its floor: the five other faces sum to 1.
        let c = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
        let x = c(0.3, 0.0, 0.6);
        let faces = [
            [c(0., 1., 0.), c(1., 1., 0.), c(1., 1., 1.), c(0., 1., 1.)],
            [c(0., 0., 0.), c(0., 1., 0.), c(0., 1., 1.), c(0., 0., 1.)],
            [c(1., 0., 0.), c(1., 0., 1.), c(1., 1., 1.), c(1., 1., 0.)],
            [c(0., 0., 0.), c(1., 0., 0.), c(1., 1., 0.), c(0., 1., 0.)],
            [c(0., 0., 1.), c(0., 1., 1.), c(1., 1., 1.), c(1., 0., 1.)],
        ];
        let sum: f64 = faces.iter().map(|f| point_to_polygon_unsided(x, DVec3::Y, f)).sum();
        assert!((sum - 1.0).abs() < 1e-12, "{sum}");
    }
}
