//! Single-ray traversal of the 8-wide BVH: closest hit and any hit, generic over the
//! [`Kernel`] that tests boxes and triangles.
//!
//! Closest hit is the ordered depth-first traversal of wide BVHs (Wald, Benthin & Boulos
//! 2008; Ernst & Greiner 2008) as Embree runs it (Wald et al. 2014): the ray meets the eight
//! child boxes in one test; with one hit child it descends, with two it descends into the
//! nearer and pushes the farther, with more it sorts them by entry distance and pushes all
//! but the nearest. Stack entries keep their entry distance, so a popped subtree that lies
//! beyond the closest hit found since is dropped without touching its node. Any hit needs no
//! order: children are pushed as found and the first accepted triangle ends the query.
//!
//! The stack holds 64 entries inline and spills to the heap beyond that, so no tree shape
//! can overflow it (a balanced tree over 10⁹ triangles needs under 80).

use super::kernel::{lane_uv, Kernel, RayPre};
use super::layout::{
    child, is_leaf, leaf_range, node_at, packet_at, prim, ChildRef, NodeUnits, NODE_UNITS, PACKET, PACKET_UNITS, WIDTH,
};
use super::{Bvh, Hit, Ray};

const INLINE: usize = 64;

/// A traversal stack: a fixed inline array, spilling to a vector on deep trees.
struct Stack<T: Copy + Default> {
    inline: [T; INLINE],
    len: usize,
    spill: Vec<T>,
}

impl<T: Copy + Default> Stack<T> {
    #[inline(always)]
    fn new() -> Self {
        Stack { inline: [T::default(); INLINE], len: 0, spill: Vec::new() }
    }

    #[inline(always)]
    fn push(&mut self, v: T) {
        if self.len < INLINE {
            self.inline[self.len] = v;
        } else {
            self.spill.push(v);
        }
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        if self.len < INLINE {
            Some(self.inline[self.len])
        } else {
            self.spill.pop()
        }
    }
}

/// Closest hit with `tmin < t < tmax` among triangles with `skip(prim) == false`.
#[inline(always)]
pub(super) fn closest<K: Kernel>(k: K, bvh: &Bvh, ray: &Ray, skip: impl Fn(u32) -> bool) -> Option<Hit> {
    // A NaN ray would pass every box test (NaN slabs are dropped) and hit nothing.
    if bvh.units.is_empty() || !(ray.origin.is_finite() && ray.dir.is_finite()) {
        return None;
    }
    let r = RayPre::new(ray);
    let mut tmax = ray.tmax;
    // (packet, lane) of the closest accepted hit.
    let mut best: Option<(usize, usize)> = None;
    let mut stack: Stack<(ChildRef, f32)> = Stack::new();
    let mut cur: ChildRef = 0;
    'traverse: loop {
        // Descend through interior nodes to a leaf.
        while !is_leaf(cur) {
            let node = node_at(&bvh.units, cur as usize);
            let mut dist = [0f32; WIDTH];
            let mut mask = k.boxes(node, &r, tmax, &mut dist);
            prefetch_children(k, bvh, node, mask);
            if mask == 0 {
                match pop_closer(&mut stack, tmax) {
                    Some(c) => {
                        cur = c;
                        continue;
                    }
                    None => break 'traverse,
                }
            }
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if mask == 0 {
                cur = child(node, i);
                continue;
            }
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if mask == 0 {
                let (near, far) = if dist[i] <= dist[j] { (i, j) } else { (j, i) };
                stack.push((child(node, far), dist[far]));
                cur = child(node, near);
                continue;
            }
            // Three or more: sort by entry distance, farthest first, and push all but the
            // nearest (insertion sort; at most eight).
            let mut hits = [(0 as ChildRef, 0f32); WIDTH];
            hits[0] = (child(node, i), dist[i]);
            hits[1] = (child(node, j), dist[j]);
            let mut n = 2;
            while mask != 0 {
                let c = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                hits[n] = (child(node, c), dist[c]);
                n += 1;
            }
            for a in 1..n {
                let x = hits[a];
                let mut b = a;
                while b > 0 && hits[b - 1].1 < x.1 {
                    hits[b] = hits[b - 1];
                    b -= 1;
                }
                hits[b] = x;
            }
            for h in &hits[..n - 1] {
                stack.push(*h);
            }
            cur = hits[n - 1].0;
        }
        // A leaf: its packets.
        let (start, count) = leaf_range(cur);
        for pi in 0..count {
            let at = start + pi * PACKET_UNITS;
            let p = packet_at(&bvh.units, at);
            let mut t = [0f32; PACKET];
            let mut mask = k.triangles(p, &r, tmax, &mut t);
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if t[l] < tmax && !skip(prim(p, l)) {
                    tmax = t[l];
                    best = Some((at, l));
                }
            }
        }
        match pop_closer(&mut stack, tmax) {
            Some(c) => cur = c,
            None => break,
        }
    }
    let (at, l) = best?;
    let p = packet_at(&bvh.units, at);
    let (u, v) = lane_uv(p, &r, l);
    Some(Hit { t: tmax, u, v, prim: prim(p, l) })
}

/// Prefetches the nodes and leaf packets of the children in `mask`, so that their cache
/// misses overlap (Embree does the same).
#[inline(always)]
fn prefetch_children<K: Kernel>(k: K, bvh: &Bvh, node: &NodeUnits, mut mask: u32) {
    while mask != 0 {
        let c = child(node, mask.trailing_zeros() as usize);
        mask &= mask - 1;
        if is_leaf(c) {
            if let Some(p) = bvh.units.get(leaf_range(c).0..).and_then(|u| u.first_chunk::<PACKET_UNITS>()) {
                k.prefetch(p);
            }
        } else if let Some(n) = bvh.units.get(c as usize..).and_then(|u| u.first_chunk::<NODE_UNITS>()) {
            k.prefetch(n);
        }
    }
}

/// The next stacked subtree that may still hold a hit closer than `tmax`.
#[inline(always)]
fn pop_closer(stack: &mut Stack<(ChildRef, f32)>, tmax: f32) -> Option<ChildRef> {
    while let Some((c, d)) = stack.pop() {
        if d <= tmax {
            return Some(c);
        }
    }
    None
}

/// True if a triangle with `skip(prim) == false` is hit at `tmin < t < tmax`.
#[inline(always)]
pub(super) fn occluded<K: Kernel>(k: K, bvh: &Bvh, ray: &Ray, skip: impl Fn(u32) -> bool) -> bool {
    if bvh.units.is_empty() || !(ray.origin.is_finite() && ray.dir.is_finite()) {
        return false;
    }
    let r = RayPre::new(ray);
    let tmax = ray.tmax;
    let mut stack: Stack<ChildRef> = Stack::new();
    let mut cur: ChildRef = 0;
    loop {
        while !is_leaf(cur) {
            let node = node_at(&bvh.units, cur as usize);
            let mut dist = [0f32; WIDTH];
            let mut mask = k.boxes(node, &r, tmax, &mut dist);
            prefetch_children(k, bvh, node, mask);
            if mask == 0 {
                match stack.pop() {
                    Some(c) => {
                        cur = c;
                        continue;
                    }
                    None => return false,
                }
            }
            cur = child(node, mask.trailing_zeros() as usize);
            mask &= mask - 1;
            while mask != 0 {
                stack.push(child(node, mask.trailing_zeros() as usize));
                mask &= mask - 1;
            }
        }
        let (start, count) = leaf_range(cur);
        for pi in 0..count {
            let p = packet_at(&bvh.units, start + pi * PACKET_UNITS);
            let mut t = [0f32; PACKET];
            let mut mask = k.triangles(p, &r, tmax, &mut t);
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if !skip(prim(p, l)) {
                    return true;
                }
            }
        }
        match stack.pop() {
            Some(c) => cur = c,
            None => return false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stack_spills_past_its_inline_part() {
        let mut s: Stack<u32> = Stack::new();
        for i in 0..200 {
            s.push(i);
        }
        for i in (0..200).rev() {
            assert_eq!(s.pop(), Some(i));
        }
        assert_eq!(s.pop(), None);
    }
}
