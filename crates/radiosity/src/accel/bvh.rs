//! Binned-SAH bounding volume hierarchy over triangles, f32, closest-hit and any-hit.
//!
//! Build: 16 bins per axis over centroid bounds, SAH cost (Wald 2007); leaves hold at most
//! [`MAX_LEAF`] triangles. Nodes are 32 bytes (bounds + child/first index + count).
//! Triangles are stored pre-transformed for Möller–Trumbore (v0, e1, e2).
//! Traversal: front-to-back ordered, explicit stack, ray-box slab test with precomputed
//! inverse direction.

use glam::Vec3;

/// Maximum triangles per leaf.
pub const MAX_LEAF: usize = 4;
const BINS: usize = 16;

/// A ray with a parametric interval `[tmin, tmax]`.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be normalised; t is in units of this vector).
    pub dir: Vec3,
    /// Hits closer than this are ignored.
    pub tmin: f32,
    /// Hits farther than this are ignored.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `[tmin, tmax]`.
    pub fn new(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray { origin, dir, tmin, tmax }
    }
}

/// A closest hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric coordinate of v1.
    pub u: f32,
    /// Barycentric coordinate of v2.
    pub v: f32,
    /// Index of the triangle in the build input.
    pub prim: u32,
}

#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
struct Node {
    lo: [f32; 3],
    /// Leaf: first triangle; interior: index of the left child (right = left + 1).
    start: u32,
    hi: [f32; 3],
    /// Leaf: triangle count (>0); interior: 0.
    count: u32,
}

#[derive(Clone, Copy, Debug)]
struct Tri {
    v0: Vec3,
    e1: Vec3,
    e2: Vec3,
}

/// The hierarchy.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    tris: Vec<Tri>,
    /// Position in the build input of each stored triangle.
    prim_ids: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Aabb {
    lo: Vec3,
    hi: Vec3,
}
impl Aabb {
    const EMPTY: Aabb = Aabb { lo: Vec3::splat(f32::INFINITY), hi: Vec3::splat(f32::NEG_INFINITY) };
    fn grow(&mut self, p: Vec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }
    fn merge(&mut self, b: &Aabb) {
        self.lo = self.lo.min(b.lo);
        self.hi = self.hi.max(b.hi);
    }
    fn area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3::ZERO);
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
}

impl Bvh {
    /// Builds the hierarchy over `tris` (each three vertices). Degenerate triangles are
    /// kept (they are never hit).
    pub fn build(tris: &[[Vec3; 3]]) -> Bvh {
        let n = tris.len();
        if n == 0 {
            return Bvh::default();
        }
        let mut boxes = Vec::with_capacity(n);
        let mut cents = Vec::with_capacity(n);
        for t in tris {
            let mut b = Aabb::EMPTY;
            for p in t {
                b.grow(*p);
            }
            boxes.push(b);
            cents.push((b.lo + b.hi) * 0.5);
        }
        let mut idx: Vec<u32> = (0..n as u32).collect();
        let mut nodes = Vec::with_capacity(2 * n / MAX_LEAF + 1);
        nodes.push(Node::default());
        // (node, start, end)
        let mut stack = vec![(0usize, 0usize, n)];
        while let Some((ni, start, end)) = stack.pop() {
            let mut bb = Aabb::EMPTY;
            let mut cb = Aabb::EMPTY;
            for &i in &idx[start..end] {
                bb.merge(&boxes[i as usize]);
                cb.grow(cents[i as usize]);
            }
            nodes[ni].lo = bb.lo.to_array();
            nodes[ni].hi = bb.hi.to_array();
            let count = end - start;
            let make_leaf = |nodes: &mut Vec<Node>| {
                nodes[ni].start = start as u32;
                nodes[ni].count = count as u32;
            };
            if count <= 1 {
                make_leaf(&mut nodes);
                continue;
            }
            // Binned SAH over the axis of largest centroid extent (and the others).
            let mut best = (f32::INFINITY, 0usize, 0usize); // cost, axis, split bin
            let ext = cb.hi - cb.lo;
            for axis in 0..3 {
                if ext[axis] <= 0.0 {
                    continue;
                }
                let scale = BINS as f32 / ext[axis];
                let mut bin_box = [Aabb::EMPTY; BINS];
                let mut bin_cnt = [0u32; BINS];
                for &i in &idx[start..end] {
                    let b = (((cents[i as usize][axis] - cb.lo[axis]) * scale) as usize).min(BINS - 1);
                    bin_cnt[b] += 1;
                    bin_box[b].merge(&boxes[i as usize]);
                }
                let mut right_area = [0f32; BINS];
                let mut right_cnt = [0u32; BINS];
                let mut acc = Aabb::EMPTY;
                let mut c = 0;
                for b in (1..BINS).rev() {
                    acc.merge(&bin_box[b]);
                    c += bin_cnt[b];
                    right_area[b] = acc.area();
                    right_cnt[b] = c;
                }
                let mut acc = Aabb::EMPTY;
                let mut c = 0;
                for b in 0..BINS - 1 {
                    acc.merge(&bin_box[b]);
                    c += bin_cnt[b];
                    if c == 0 || right_cnt[b + 1] == 0 {
                        continue;
                    }
                    let cost = acc.area() * c as f32 + right_area[b + 1] * right_cnt[b + 1] as f32;
                    if cost < best.0 {
                        best = (cost, axis, b);
                    }
                }
            }
            let leaf_cost = bb.area() * count as f32;
            if best.0.is_infinite() {
                // All centroids coincide: a leaf if small, else split the list in half.
                if count <= MAX_LEAF {
                    make_leaf(&mut nodes);
                } else {
                    let mid = start + count / 2;
                    let l = nodes.len();
                    nodes.push(Node::default());
                    nodes.push(Node::default());
                    nodes[ni].start = l as u32;
                    nodes[ni].count = 0;
                    stack.push((l, start, mid));
                    stack.push((l + 1, mid, end));
                }
                continue;
            }
            // A traversal step costs about one triangle test.
            if count <= MAX_LEAF && leaf_cost <= best.0 + bb.area() {
                make_leaf(&mut nodes);
                continue;
            }
            let (_, axis, split) = best;
            let scale = BINS as f32 / ext[axis];
            let slice = &mut idx[start..end];
            let mut i = 0;
            let mut j = slice.len();
            while i < j {
                let b = (((cents[slice[i] as usize][axis] - cb.lo[axis]) * scale) as usize).min(BINS - 1);
                if b <= split {
                    i += 1;
                } else {
                    j -= 1;
                    slice.swap(i, j);
                }
            }
            let mid = start + i;
            let l = nodes.len();
            nodes.push(Node::default());
            nodes.push(Node::default());
            nodes[ni].start = l as u32;
            nodes[ni].count = 0;
            stack.push((l, start, mid));
            stack.push((l + 1, mid, end));
        }
        let tris_out = idx
            .iter()
            .map(|&i| {
                let t = &tris[i as usize];
                Tri { v0: t[0], e1: t[1] - t[0], e2: t[2] - t[0] }
            })
            .collect();
        Bvh { nodes, tris: tris_out, prim_ids: idx }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// True when built over no triangles.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Number of nodes (for statistics).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Memory used, in bytes.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>()
            + self.tris.len() * std::mem::size_of::<Tri>()
            + self.prim_ids.len() * 4
    }

    /// Closest hit along the ray.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_filtered(ray, |_| false)
    }

    /// Closest hit, ignoring triangles for which `skip(prim)` is true.
    pub fn intersect_filtered(&self, ray: &Ray, skip: impl Fn(u32) -> bool) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv = ray.dir.recip();
        let mut best: Option<Hit> = None;
        let mut tmax = ray.tmax;
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut node = 0u32;
        loop {
            let n = &self.nodes[node as usize];
            if n.count > 0 {
                for k in n.start..n.start + n.count {
                    if let Some((t, u, v)) = self.hit_tri(k as usize, ray, tmax) {
                        let prim = self.prim_ids[k as usize];
                        if !skip(prim) {
                            tmax = t;
                            best = Some(Hit { t, u, v, prim });
                        }
                    }
                }
            } else {
                let (l, r) = (n.start, n.start + 1);
                let dl = self.box_hit(l, ray.origin, inv, ray.tmin, tmax);
                let dr = self.box_hit(r, ray.origin, inv, ray.tmin, tmax);
                match (dl, dr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b { (l, r) } else { (r, l) };
                        stack[sp] = far;
                        sp += 1;
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            if sp == 0 {
                break;
            }
            sp -= 1;
            node = stack[sp];
        }
        best
    }

    /// True if anything is hit within `[tmin, tmax]`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_filtered(ray, |_| false)
    }

    /// True if a triangle with `skip(prim) == false` is hit within `[tmin, tmax]`.
    pub fn occluded_filtered(&self, ray: &Ray, skip: impl Fn(u32) -> bool) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let inv = ray.dir.recip();
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut node = 0u32;
        loop {
            let n = &self.nodes[node as usize];
            if n.count > 0 {
                for k in n.start..n.start + n.count {
                    if self.hit_tri(k as usize, ray, ray.tmax).is_some() && !skip(self.prim_ids[k as usize]) {
                        return true;
                    }
                }
            } else {
                let (l, r) = (n.start, n.start + 1);
                let dl = self.box_hit(l, ray.origin, inv, ray.tmin, ray.tmax);
                let dr = self.box_hit(r, ray.origin, inv, ray.tmin, ray.tmax);
                match (dl, dr) {
                    (Some(_), Some(_)) => {
                        stack[sp] = r;
                        sp += 1;
                        node = l;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            node = stack[sp];
        }
    }

    #[inline(always)]
    fn box_hit(&self, i: u32, o: Vec3, inv: Vec3, tmin: f32, tmax: f32) -> Option<f32> {
        let n = &self.nodes[i as usize];
        let t0 = (Vec3::from_array(n.lo) - o) * inv;
        let t1 = (Vec3::from_array(n.hi) - o) * inv;
        let tn = t0.min(t1).max_element().max(tmin);
        let tf = t0.max(t1).min_element().min(tmax);
        // NaN (0 * inf) compares false: treated as a miss only when both bounds are NaN.
        if tn <= tf {
            Some(tn)
        } else {
            None
        }
    }

    /// Möller–Trumbore; returns (t, u, v) for a hit in (tmin, tmax).
    #[inline(always)]
    fn hit_tri(&self, k: usize, ray: &Ray, tmax: f32) -> Option<(f32, f32, f32)> {
        let tri = &self.tris[k];
        let p = ray.dir.cross(tri.e2);
        let det = tri.e1.dot(p);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv_det = 1.0 / det;
        let s = ray.origin - tri.v0;
        let u = s.dot(p) * inv_det;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(tri.e1);
        let v = ray.dir.dot(q) * inv_det;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = tri.e2.dot(q) * inv_det;
        if t > ray.tmin && t < tmax {
            Some((t, u, v))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn random_tris(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let c = Vec3::new(rng.random(), rng.random(), rng.random()) * 10.0;
                let mut r = || Vec3::new(rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5);
                [c + r(), c + r(), c + r()]
            })
            .collect()
    }

    fn brute(tris: &[[Vec3; 3]], ray: &Ray) -> Option<(f32, u32)> {
        let mut best: Option<(f32, u32)> = None;
        for (i, t) in tris.iter().enumerate() {
            let one = Bvh::build(&[*t]);
            if let Some(h) = one.intersect(&Ray { tmax: best.map_or(ray.tmax, |b| b.0), ..*ray }) {
                best = Some((h.t, i as u32));
            }
        }
        best
    }

    #[test]
    fn closest_and_any_hit_match_brute_force() {
        let tris = random_tris(500, 1);
        let bvh = Bvh::build(&tris);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2);
        let mut hits = 0;
        for _ in 0..2000 {
            let o = Vec3::new(rng.random(), rng.random(), rng.random()) * 12.0 - 1.0;
            let d = Vec3::new(rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5);
            let ray = Ray::new(o, d, 0.0, f32::INFINITY);
            let a = bvh.intersect(&ray).map(|h| (h.t, h.prim));
            let b = brute(&tris, &ray);
            assert_eq!(a.is_some(), b.is_some());
            if let (Some(a), Some(b)) = (a, b) {
                assert!((a.0 - b.0).abs() <= 1e-5 * a.0.max(1.0));
                hits += 1;
            }
            assert_eq!(bvh.occluded(&ray), b.is_some());
        }
        assert!(hits > 100);
    }

    #[test]
    fn filter_skips_primitives() {
        let tris = vec![
            [Vec3::new(-1., -1., 1.), Vec3::new(1., -1., 1.), Vec3::new(0., 1., 1.)],
            [Vec3::new(-1., -1., 2.), Vec3::new(1., -1., 2.), Vec3::new(0., 1., 2.)],
        ];
        let bvh = Bvh::build(&tris);
        let ray = Ray::new(Vec3::ZERO, Vec3::Z, 0.0, 10.0);
        assert_eq!(bvh.intersect(&ray).unwrap().prim, 0);
        assert_eq!(bvh.intersect_filtered(&ray, |p| p == 0).unwrap().prim, 1);
        assert!(!bvh.occluded_filtered(&ray, |_| true));
        assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::Z, 0.0, 0.5)));
    }
}
