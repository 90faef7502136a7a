//! Deterministic sampling helpers.
//!
//! Every random stream is derived from (user seed, a stream id such as an element index),
//! never from a thread, so results are identical whatever the number of threads.

use rand::SeedableRng;

/// The random generator used everywhere: PCG-64 (MCG variant), small and fast.
pub type Rng = rand_pcg::Pcg64Mcg;

/// SplitMix64 finaliser: a good 64-bit hash of one word.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A generator for stream `stream` of seed `seed`.
#[inline]
pub fn rng_for(seed: u64, stream: u64) -> Rng {
    Rng::seed_from_u64(mix64(seed ^ mix64(stream.wrapping_add(0x51_7CC1_B727_220A))))
}

/// A uniform number in [0,1) from 64 random bits.
#[inline]
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// `n × n` jittered points in [0,1)² (stratified), using `rng`.
pub fn stratified(n: usize, rng: &mut Rng, out: &mut Vec<(f64, f64)>) {
    use rand::RngExt;
    out.clear();
    let inv = 1.0 / n as f64;
    for j in 0..n {
        for i in 0..n {
            let (a, b): (f64, f64) = (rng.random(), rng.random());
            out.push(((i as f64 + a) * inv, (j as f64 + b) * inv));
        }
    }
}

/// Cosine-weighted direction about +Z for (u1, u2) ∈ [0,1)² (Malley's method).
#[inline]
pub fn cosine_hemisphere(u1: f64, u2: f64) -> glam::DVec3 {
    let r = u1.sqrt();
    let phi = 2.0 * std::f64::consts::PI * u2;
    glam::DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt())
}

/// An orthonormal basis (t, b) completing unit vector `n` (Duff et al. 2017).
#[inline]
pub fn basis(n: glam::DVec3) -> (glam::DVec3, glam::DVec3) {
    let sign = 1f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        glam::DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        glam::DVec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// The i-th point of the 2-D Halton-like (2,3) sequence scrambled by a rotation
/// (Cranley–Patterson) `shift`.
#[inline]
pub fn halton2(i: u32, shift: (f64, f64)) -> (f64, f64) {
    let a = radical_inverse(2, i as u64) + shift.0;
    let b = radical_inverse(3, i as u64) + shift.1;
    (a - a.floor(), b - b.floor())
}

/// Radical inverse of `i` in `base`.
#[inline]
pub fn radical_inverse(base: u64, mut i: u64) -> f64 {
    let inv = 1.0 / base as f64;
    let mut f = inv;
    let mut r = 0.0;
    while i > 0 {
        r += f * (i % base) as f64;
        i /= base;
        f *= inv;
    }
    r
}

/// A spherical triangle (unit vertex directions) sampled uniformly in solid angle (Arvo
/// 1995, "Stratified sampling of spherical triangles"): the final gather's sky portals.
#[derive(Clone, Copy, Debug)]
pub struct SphericalTriangle {
    a: glam::DVec3,
    b: glam::DVec3,
    c: glam::DVec3,
    alpha: f64,
    /// Solid angle, steradians.
    pub area: f64,
}

impl SphericalTriangle {
    /// The triangle of unit directions `a`, `b`, `c`; None when it subtends (almost) no
    /// solid angle (its angles' excess below 1e-9 sr, where the angle sum cancels).
    pub fn new(a: glam::DVec3, b: glam::DVec3, c: glam::DVec3) -> Option<Self> {
        // The angle at p between the great circles towards q and r.
        let angle = |p: glam::DVec3, q: glam::DVec3, r: glam::DVec3| {
            let (u, v) = (p.cross(q), p.cross(r));
            let (lu, lv) = (u.length(), v.length());
            if lu > 0.0 && lv > 0.0 {
                (u.dot(v) / (lu * lv)).clamp(-1.0, 1.0).acos()
            } else {
                f64::NAN
            }
        };
        let alpha = angle(a, b, c);
        let area = alpha + angle(b, c, a) + angle(c, a, b) - std::f64::consts::PI;
        (area.is_finite() && area > 1e-9).then_some(SphericalTriangle { a, b, c, alpha, area })
    }

    /// The direction for `(u1, u2)` ∈ [0,1)², uniform in solid angle (density `1/area`),
    /// keeping stratification.
    pub fn sample(&self, u1: f64, u2: f64) -> glam::DVec3 {
        let (a, b, c) = (self.a, self.b, self.c);
        // The sub-triangle A B Ĉ of area u1·area fixes Ĉ on the arc AC ...
        let (s, t) = (u1 * self.area - self.alpha).sin_cos();
        let (sa, ca) = self.alpha.sin_cos();
        let u = t - ca;
        let v = s + sa * a.dot(b);
        let q = (((v * t - u * s) * ca - v) / ((v * s + u * t) * sa)).clamp(-1.0, 1.0);
        let c_hat = a * q + (c - a * c.dot(a)).normalize_or_zero() * (1.0 - q * q).max(0.0).sqrt();
        // ... and u2 a point on the arc B Ĉ, uniform in the area it sweeps.
        let z = 1.0 - u2 * (1.0 - c_hat.dot(b));
        b * z + (c_hat - b * c_hat.dot(b)).normalize_or_zero() * (1.0 - z * z).max(0.0).sqrt()
    }
}

/// Direction `k` of `m` spread evenly over the unit sphere (a Fibonacci lattice: equal-area
/// bands in z, the golden angle between consecutive points).
pub fn fibonacci_sphere(k: u32, m: u32) -> glam::DVec3 {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - (2.0 * k as f64 + 1.0) / m as f64;
    let r = (1.0 - z * z).max(0.0).sqrt();
    glam::DVec3::new(r * (golden * k as f64).cos(), r * (golden * k as f64).sin(), z)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    /// Directions drawn uniformly over a spherical triangle, weighted by cos θ, integrate to
    /// π·F (the point-to-polygon factor's contour integral) for triangles near and far,
    /// large and grazing; every direction falls inside the triangle.
    #[test]
    fn spherical_triangle_samples_integrate_the_cosine_exactly() {
        let x = DVec3::ZERO;
        let n = DVec3::Y;
        let cases = [
            [DVec3::new(-1.0, 1.0, -1.0), DVec3::new(1.0, 1.0, -1.0), DVec3::new(0.0, 1.0, 1.5)],
            [DVec3::new(-8.0, 0.5, -8.0), DVec3::new(8.0, 0.5, -8.0), DVec3::new(8.0, 0.5, 8.0)],
            [DVec3::new(2.0, 3.0, 0.1), DVec3::new(2.3, 3.0, 0.1), DVec3::new(2.0, 3.4, 0.3)],
            [DVec3::new(0.2, 0.1, 1.0), DVec3::new(3.0, 2.0, 1.0), DVec3::new(-1.0, 4.0, 1.0)],
        ];
        for tri in cases {
            let exact = std::f64::consts::PI * crate::geom::kernel::point_to_polygon_unsided(x, n, &tri);
            let st = SphericalTriangle::new(tri[0].normalize(), tri[1].normalize(), tri[2].normalize()).unwrap();
            let mut pts = Vec::new();
            stratified(64, &mut rng_for(1, 0), &mut pts);
            let plane = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
            let mut sum = 0.0;
            for &(u, v) in &pts {
                let d = st.sample(u, v);
                assert!((d.length() - 1.0).abs() < 1e-9);
                // Inside: the ray meets the triangle's plane within its edges.
                let t = plane.dot(tri[0]) / plane.dot(d);
                let q = d * t;
                let inside = (0..3).all(|k| plane.dot((tri[(k + 1) % 3] - tri[k]).cross(q - tri[k])) >= -1e-9 * plane.length_squared());
                assert!(t > 0.0 && inside, "{d} outside {tri:?}");
                sum += d.dot(n).max(0.0);
            }
            let estimate = st.area * sum / pts.len() as f64;
            eprintln!("{tri:?}: Ω {:.5}, ∫cos {estimate:.6} against π·F {exact:.6}", st.area);
            assert!((estimate - exact).abs() <= 1e-3 * exact, "{estimate} against {exact}");
        }
    }
}
