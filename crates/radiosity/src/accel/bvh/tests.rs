//! The BVH against brute force: every query must return exactly what testing every
//! triangle returns (same triangle, same t, u, v bit for bit), for both kernels, and the
//! hits must agree with an independent f64 Möller–Trumbore.

use glam::Vec3;
use rand::{RngExt, SeedableRng};

use super::kernel::{lane_uv, Kernel, Portable, RayPre};
use super::layout::{prim, PacketUnits, TriPacket};
use super::*;

type Rng = rand_pcg::Pcg64Mcg;

fn rng(seed: u64) -> Rng {
    Rng::seed_from_u64(seed)
}

fn v3(r: &mut Rng) -> Vec3 {
    Vec3::new(r.random(), r.random(), r.random())
}

/// Small random triangles in [0, 10]³.
fn random_tris(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mut r = rng(seed);
    (0..n)
        .map(|_| {
            let c = v3(&mut r) * 10.0;
            [c + v3(&mut r) - 0.5, c + v3(&mut r) - 0.5, c + v3(&mut r) - 0.5]
        })
        .collect()
}

/// Random rays through the cube; some with zero direction components, some with finite
/// intervals.
fn random_rays(n: usize, seed: u64) -> Vec<Ray> {
    let mut r = rng(seed);
    (0..n)
        .map(|i| {
            let o = v3(&mut r) * 12.0 - 1.0;
            let mut d = v3(&mut r) - 0.5;
            if i % 7 == 0 {
                d.x = 0.0;
            }
            if i % 11 == 0 {
                d.y = -0.0;
                d.z = 0.0;
            }
            if d == Vec3::ZERO {
                d = Vec3::X;
            }
            let (tmin, tmax) = match i % 4 {
                0 => (0.0, f32::INFINITY),
                1 => (0.5, f32::INFINITY),
                2 => (0.0, 8.0),
                _ => (1.0, 20.0),
            };
            Ray::new(o, d, tmin, tmax)
        })
        .collect()
}

/// The BVH once per available kernel.
fn kernels(tris: &[[Vec3; 3]]) -> Vec<(&'static str, Bvh)> {
    let bvh = Bvh::build(tris);
    #[allow(unused_mut)]
    let mut portable = bvh.clone();
    #[cfg(target_arch = "x86_64")]
    {
        portable.avx2 = None;
    }
    let mut out = vec![("portable", portable)];
    #[cfg(target_arch = "x86_64")]
    if bvh.avx2.is_some() {
        out.push(("avx2", bvh));
    }
    out
}

/// Every triangle tested with the portable kernel: the closest accepted hit.
struct Brute {
    packets: Vec<PacketUnits>,
}

impl Brute {
    fn new(tris: &[[Vec3; 3]]) -> Brute {
        let packets = tris
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let mut p = TriPacket::EMPTY;
                if t.iter().all(|p| p.is_finite()) {
                    p.set(0, t, i as u32);
                }
                p.to_units()
            })
            .collect();
        Brute { packets }
    }

    fn closest(&self, ray: &Ray, skip: impl Fn(u32) -> bool) -> Option<Hit> {
        let r = RayPre::new(ray);
        let mut best: Option<Hit> = None;
        for p in &self.packets {
            let tmax = best.map_or(ray.tmax, |h| h.t);
            let mut t = [0.0; 4];
            if Portable.triangles(p, &r, tmax, &mut t) & 1 != 0 && !skip(prim(p, 0)) {
                let (u, v) = lane_uv(p, &r, 0);
                best = Some(Hit { t: t[0], u, v, prim: prim(p, 0) });
            }
        }
        best
    }
}

/// Möller–Trumbore in f64: (t, u, v) of a proper hit, ignoring the interval.
fn reference_f64(t: &[Vec3; 3], ray: &Ray) -> Option<(f64, f64, f64)> {
    let [a, b, c] = t.map(|p| p.as_dvec3());
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    Some((e2.dot(q) / det, u, v))
}

fn check_against_brute(tris: &[[Vec3; 3]], rays: &[Ray], skip: impl Fn(u32) -> bool + Copy) -> usize {
    let brute = Brute::new(tris);
    let mut hits = 0;
    for (name, bvh) in kernels(tris) {
        hits = 0;
        for (i, ray) in rays.iter().enumerate() {
            let want = brute.closest(ray, skip);
            let got = bvh.intersect_filtered(ray, skip);
            assert_eq!(got, want, "{name}: closest hit of ray {i} {ray:?}");
            assert_eq!(bvh.occluded_filtered(ray, skip), want.is_some(), "{name}: any hit of ray {i} {ray:?}");
            if let Some(h) = got {
                hits += 1;
                assert!(h.t > ray.tmin && h.t < ray.tmax);
                let (t, u, v) = reference_f64(&tris[h.prim as usize], ray).expect("a proper hit");
                let tol = 1e-3 * t.abs().max(1.0);
                assert!((t - h.t as f64).abs() < tol, "{name}: t {} vs f64 {t}", h.t);
                assert!((u - h.u as f64).abs() < 1e-3 && (v - h.v as f64).abs() < 1e-3, "{name}: u, v");
            }
        }
    }
    hits
}

#[test]
fn closest_and_any_hit_match_brute_force() {
    let tris = random_tris(600, 1);
    let rays = random_rays(3000, 2);
    let hits = check_against_brute(&tris, &rays, |_| false);
    assert!(hits > 250, "{hits} hits");
}

#[test]
fn larger_scene_matches_brute_force() {
    // Deep enough for several wide levels and the parallel build.
    let tris = random_tris(20_000, 3);
    let rays = random_rays(1500, 4);
    let hits = check_against_brute(&tris, &rays, |_| false);
    assert!(hits > 700, "{hits} hits");
}

#[test]
fn filters_skip_primitives() {
    let tris = random_tris(600, 5);
    let rays = random_rays(2000, 6);
    let hits = check_against_brute(&tris, &rays, |p| p % 3 == 0);
    assert!(hits > 100, "{hits} hits");
    // Skipping everything hits nothing.
    for (_, bvh) in kernels(&tris) {
        for ray in &rays {
            assert_eq!(bvh.intersect_filtered(ray, |_| true), None);
            assert!(!bvh.occluded_filtered(ray, |_| true));
        }
    }
}

#[test]
fn filter_on_two_stacked_triangles() {
    let tris = vec![
        [Vec3::new(-1., -1., 1.), Vec3::new(1., -1., 1.), Vec3::new(0., 1., 1.)],
        [Vec3::new(-1., -1., 2.), Vec3::new(1., -1., 2.), Vec3::new(0., 1., 2.)],
    ];
    for (_, bvh) in kernels(&tris) {
        let ray = Ray::new(Vec3::ZERO, Vec3::Z, 0.0, 10.0);
        assert_eq!(bvh.intersect(&ray).unwrap().prim, 0);
        assert_eq!(bvh.intersect_filtered(&ray, |p| p == 0).unwrap().prim, 1);
        assert!(!bvh.occluded_filtered(&ray, |_| true));
        assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::Z, 0.0, 0.5)));
    }
}

#[test]
fn interval_is_open_and_barycentrics_locate_the_hit() {
    let tri = [Vec3::new(-1., -1., 1.), Vec3::new(3., -1., 1.), Vec3::new(-1., 3., 1.)];
    for (_, bvh) in kernels(&[tri]) {
        let o = Vec3::new(0.0, 0.5, 0.0);
        let hit = |tmin, tmax| bvh.intersect(&Ray::new(o, Vec3::Z, tmin, tmax));
        assert_eq!(hit(0.0, 1.0), None, "t = tmax is outside");
        assert_eq!(hit(1.0, 5.0), None, "t = tmin is outside");
        let h = hit(0.999, 1.001).expect("hit");
        assert_eq!(h.t, 1.0);
        assert_eq!(h.prim, 0);
        let p = tri[0] + (tri[1] - tri[0]) * h.u + (tri[2] - tri[0]) * h.v;
        assert!((p - (o + Vec3::Z * h.t)).length() < 1e-6);
        assert!((h.u - 0.25).abs() < 1e-6 && (h.v - 0.375).abs() < 1e-6, "{h:?}");
        // From behind, and with an unnormalised direction: t in units of dir.
        let h = bvh.intersect(&Ray::new(Vec3::new(0.0, 0.5, 3.0), Vec3::Z * -4.0, 0.0, 1.0)).unwrap();
        assert_eq!(h.t, 0.5);
        assert!(bvh.occluded(&Ray::new(o, Vec3::Z, 0.0, 1.5)));
        assert!(!bvh.occluded(&Ray::new(o, Vec3::Z, 0.0, 1.0)));
    }
}

/// A closed box of small triangles plus clutter inside; rays leave surface points.
fn box_scene() -> Vec<[Vec3; 3]> {
    let mut tris = Vec::new();
    let n = 12;
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            for i in 0..n {
                for j in 0..n {
                    let p = |a: usize, b: usize| {
                        let mut v = [0.0f32; 3];
                        v[axis] = side;
                        v[(axis + 1) % 3] = a as f32 / n as f32;
                        v[(axis + 2) % 3] = b as f32 / n as f32;
                        Vec3::from_array(v)
                    };
                    tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
                    tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
                }
            }
        }
    }
    tris.extend(random_tris(200, 7).iter().map(|t| t.map(|p| p * 0.08 + Vec3::splat(0.05))));
    tris
}

#[test]
fn rays_leaving_surfaces_match_brute_force() {
    let tris = box_scene();
    let brute = Brute::new(&tris);
    let mut r = rng(8);
    let mut rays = Vec::new();
    for _ in 0..1500 {
        let k = r.random_range(0..tris.len());
        let [a, b, c] = tris[k];
        let (s, t) = (r.random::<f32>().sqrt(), r.random::<f32>());
        let p = a * (1.0 - s) + b * (s * (1.0 - t)) + c * (s * t);
        let q = tris[r.random_range(0..tris.len())][0] * 0.98 + Vec3::splat(0.01);
        rays.push((k as u32, Ray::new(p, v3(&mut r) - 0.5, 0.0, f32::INFINITY)));
        // A visibility segment to another surface point, as SceneRays casts it.
        rays.push((k as u32, Ray::new(p, q - p, 1e-4, 1.0 - 1e-4)));
    }
    for (name, bvh) in kernels(&tris) {
        let mut hits = 0;
        for (k, ray) in &rays {
            let skip = |p: u32| p == *k;
            let want = brute.closest(ray, skip);
            assert_eq!(bvh.intersect_filtered(ray, skip), want, "{name}: {ray:?}");
            assert_eq!(bvh.occluded_filtered(ray, skip), want.is_some(), "{name}: {ray:?}");
            hits += want.is_some() as usize;
            // Unfiltered too: the origin's own triangle may or may not count at t ≈ 0,
            // but the BVH must agree with brute force on it.
            assert_eq!(bvh.intersect(ray), brute.closest(ray, |_| false), "{name}: {ray:?}");
        }
        // About half the rays leave the box through their own wall; the other half hit it.
        assert!(hits > 700, "{name}: {hits}");
    }
}

#[test]
fn segments_lying_in_a_floor_match_brute_force() {
    // A floor at y = 0 of many triangles, walls meeting it (edges at y = 0),
    // and segments between floor points: direction y is exactly 0 and the rays lie in the
    // faces of every box flush with the floor. Whether such a segment is blocked by a
    // wall's bottom edge must not depend on the tree.
    let mut tris = Vec::new();
    let n = 16;
    for i in 0..n {
        for j in 0..n {
            let p = |a: usize, b: usize| Vec3::new(a as f32, 0.0, b as f32) * (1.0 / n as f32);
            tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    let mut r = rng(13);
    for _ in 0..60 {
        let a = Vec3::new(r.random(), 0.0, r.random());
        let b = a + Vec3::new(r.random::<f32>() - 0.5, 0.0, r.random::<f32>() - 0.5) * 0.3;
        // Half stand on the floor, half hang below it (boxes flush with the floor's top,
        // like the sides of a table under a segment across its top).
        let up = if r.random::<bool>() { 1.0 } else { -1.0 };
        let h = Vec3::new(0.0, up * (r.random::<f32>() * 0.2 + 0.01), 0.0);
        tris.push([a, b, b + h]);
        tris.push([a, b + h, a + h]);
    }
    let floor = (2 * n * n) as u32;
    let mut rays = Vec::new();
    for _ in 0..3000 {
        let a = Vec3::new(r.random(), 0.0, r.random());
        let b = Vec3::new(r.random(), 0.0, r.random());
        rays.push(Ray::new(a, b - a, 1e-4, 1.0 - 1e-4));
        // And along the axes, with zero x or z too.
        rays.push(Ray::new(a, Vec3::new(b.x - a.x, 0.0, 0.0), 1e-4, 1.0 - 1e-4));
        rays.push(Ray::new(a, Vec3::new(0.0, -0.0, b.z - a.z), 1e-4, 1.0 - 1e-4));
    }
    let brute = Brute::new(&tris);
    for (name, bvh) in kernels(&tris) {
        let mut blocked = 0;
        for ray in &rays {
            // Floor triangles are coplanar with the segment: never hit.
            let want = brute.closest(ray, |_| false);
            assert!(want.is_none_or(|h| h.prim >= floor));
            assert_eq!(bvh.intersect(ray), want, "{name}: {ray:?}");
            assert_eq!(bvh.occluded(ray), want.is_some(), "{name}: {ray:?}");
            blocked += want.is_some() as usize;
        }
        assert!(blocked > 500 && blocked < 8500, "{name}: {blocked} blocked");
    }
}

#[test]
fn non_finite_rays_hit_nothing() {
    let tris = random_tris(200, 14);
    for (_, bvh) in kernels(&tris) {
        for (o, d) in [
            (Vec3::splat(5.0), Vec3::NAN),
            (Vec3::NAN, Vec3::X),
            (Vec3::splat(f32::INFINITY), Vec3::X),
            (Vec3::splat(5.0), Vec3::new(f32::INFINITY, 0.0, 0.0)),
        ] {
            let ray = Ray::new(o, d, 0.0, f32::INFINITY);
            assert_eq!(bvh.intersect(&ray), None);
            assert!(!bvh.occluded(&ray));
        }
    }
}

#[test]
fn degenerate_and_non_finite_triangles_are_never_hit() {
    let mut tris = random_tris(300, 9);
    let p = Vec3::new(5.0, 5.0, 5.0);
    let bad = [
        [p, p, p],                                                   // a point
        [p, p + Vec3::X, p + 2.0 * Vec3::X],                         // collinear
        [p, p + Vec3::Y, p + Vec3::Y],                               // repeated vertex
        [Vec3::NAN, p, p + Vec3::X],                                 // NaN
        [p, Vec3::new(f32::INFINITY, 0.0, 0.0), p + Vec3::Y],        // infinite
        [Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY), p], // both
    ];
    let first_bad = tris.len() as u32;
    tris.extend_from_slice(&bad);
    let mut rays = random_rays(1500, 10);
    // Rays straight at the degenerate ones.
    for k in 0..200 {
        let o = Vec3::new(k as f32 * 0.01, 0.3, -1.0);
        rays.push(Ray::new(o, p - o, 0.0, f32::INFINITY));
        rays.push(Ray::new(p - Vec3::X, Vec3::X, 0.0, f32::INFINITY));
    }
    check_against_brute(&tris, &rays, |_| false);
    for (_, bvh) in kernels(&tris) {
        assert_eq!(bvh.len(), 306);
        for ray in &rays {
            if let Some(h) = bvh.intersect(ray) {
                assert!(h.prim < first_bad, "hit degenerate triangle {}", h.prim);
            }
        }
    }
    // Only non-finite input: nothing to hit, but the triangles are counted.
    let bvh = Bvh::build(&bad[3..]);
    assert_eq!((bvh.len(), bvh.is_empty(), bvh.node_count()), (3, false, 0));
    assert!(bvh.intersect(&rays[0]).is_none() && !bvh.occluded(&rays[0]));
}

#[test]
fn empty_input() {
    let bvh = Bvh::build(&[]);
    assert!(bvh.is_empty());
    assert_eq!((bvh.len(), bvh.node_count(), bvh.memory_bytes()), (0, 0, 0));
    let ray = Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY);
    assert_eq!(bvh.intersect(&ray), None);
    assert!(!bvh.occluded(&ray));
    assert!(!bvh.occluded_filtered(&ray, |_| false));
}

#[test]
fn coincident_triangles_split_by_median() {
    // 3000 copies of one triangle: no plane separates their centroids.
    let tri = [Vec3::new(-1., -1., 1.), Vec3::new(1., -1., 1.), Vec3::new(0., 1., 1.)];
    let tris = vec![tri; 3000];
    for (_, bvh) in kernels(&tris) {
        assert!(bvh.node_count() > 10 && bvh.memory_bytes() < 2_000_000);
        let ray = Ray::new(Vec3::ZERO, Vec3::Z, 0.0, 10.0);
        assert_eq!(bvh.intersect(&ray).unwrap().t, 1.0);
        assert!(bvh.occluded(&ray));
        assert_eq!(bvh.intersect_filtered(&ray, |p| p != 1234).unwrap().prim, 1234);
        assert!(bvh.occluded_filtered(&ray, |p| p != 2999));
        assert!(!bvh.occluded_filtered(&ray, |p| p < 3000));
    }
}

#[test]
fn exponentially_spread_triangles_match_brute_force() {
    // Sizes and positions over 30 octaves: an unbalanced SAH tree.
    let mut r = rng(11);
    let tris: Vec<[Vec3; 3]> = (0..3000)
        .map(|i| {
            let s = 2f32.powi(-(i % 30));
            let c = v3(&mut r) * s;
            [c, c + Vec3::X * s * 0.3, c + Vec3::Y * s * 0.3]
        })
        .collect();
    let rays: Vec<Ray> = (0..1500)
        .map(|i| {
            let s = 2f32.powi(-(i % 30));
            let o = Vec3::new(r.random::<f32>() * s, r.random::<f32>() * s, -1.0);
            Ray::new(o, Vec3::new(0.0, 0.0, 1.0) + (v3(&mut r) - 0.5) * 1e-3, 0.0, f32::INFINITY)
        })
        .collect();
    let hits = check_against_brute(&tris, &rays, |_| false);
    assert!(hits > 300, "{hits} hits");
}

#[test]
fn tree_is_compact() {
    let tris = random_tris(20_000, 12);
    let bvh = Bvh::build(&tris);
    // About one packet per 2–4 triangles and one node per 8 leaves or so.
    assert!(bvh.node_count() < 20_000 / 8, "{} nodes", bvh.node_count());
    assert!(bvh.memory_bytes() < 20_000 * 120, "{} bytes", bvh.memory_bytes());
    let st = bvh.stats();
    assert_eq!(st.nodes, bvh.node_count());
    // Every triangle sits in exactly one leaf; leaves hold 1–8 triangles in 1–2 packets.
    assert!((st.triangles_per_leaf * st.leaves as f64 - 20_000.0).abs() < 0.5);
    assert!((1.0..=8.0).contains(&st.triangles_per_leaf) && st.packets >= st.leaves && st.packets <= 2 * st.leaves);
    assert!(st.children_per_node > 2.0 && st.children_per_node <= 8.0);
    assert!(st.depth >= 4 && st.depth < 20, "depth {}", st.depth);
    assert!(st.sah_nodes >= 1.0 && st.sah_leaves > 0.0);
}
