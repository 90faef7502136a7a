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
