//! Memory layout of the wide BVH: 8-wide nodes with their children's bounds stored as a
//! structure of arrays, and leaves of triangles in 4-wide packets precomputed for the
//! Möller–Trumbore test.
//!
//! The node holds, per axis, the lower and upper bounds of its (up to) eight children in
//! separate 8-float rows, so one ray is tested against all eight boxes with a handful of
//! 8-lane operations (Wald, Benthin & Boulos 2008, "Getting rid of packets"; Ernst &
//! Greiner 2008, "Multi bounding volume hierarchies"; Dammertz, Hanika & Keller 2008,
//! "Shallow bounding volume hierarchies for fast SIMD ray tracing of incoherent rays").
//! Unused child slots get an inverted box (lower = +∞, upper = −∞) that no ray can hit, so
//! the test needs no per-slot validity mask. The triangle packets follow Embree's
//! `Triangle4` (Wald et al. 2014) less its stored normal: first vertex and both edges of
//! four triangles, lane by lane, with the input index of each.

use glam::Vec3;

/// Children per node.
pub(super) const WIDTH: usize = 8;
/// Triangles per leaf packet.
pub(super) const PACKET: usize = 4;
/// The most packets one leaf may hold (encoded in three bits of a child reference).
pub(super) const MAX_LEAF_PACKETS: usize = 8;

/// Child reference: an interior node index, or (top bit set) a leaf of `1..=8` packets
/// starting at a packet index.
pub(super) type ChildRef = u32;

const LEAF_BIT: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 28;
const START_MASK: u32 = (1 << COUNT_SHIFT) - 1;
/// The most packets the leaf encoding can address (2²⁸, i.e. ~10⁹ triangles).
pub(super) const MAX_PACKETS: usize = START_MASK as usize + 1;

#[inline(always)]
pub(super) fn is_leaf(r: ChildRef) -> bool {
    r & LEAF_BIT != 0
}

/// A leaf reference to `count` (1..=8) packets from `start`.
#[inline]
pub(super) fn leaf_ref(start: usize, count: usize) -> ChildRef {
    debug_assert!((1..=MAX_LEAF_PACKETS).contains(&count) && start < MAX_PACKETS);
    LEAF_BIT | (((count - 1) as u32) << COUNT_SHIFT) | start as u32
}

/// (first packet, packet count) of a leaf reference.
#[inline(always)]
pub(super) fn leaf_range(r: ChildRef) -> (usize, usize) {
    ((r & START_MASK) as usize, (((r >> COUNT_SHIFT) & 7) + 1) as usize)
}

/// An 8-wide node: children's bounds as rows `[lo_x, hi_x, lo_y, hi_y, lo_z, hi_z]`, one
/// lane per child, then the child references. 256 bytes, four cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Node {
    /// `bounds[2·axis]` lower, `bounds[2·axis + 1]` upper bound of each child.
    pub bounds: [[f32; WIDTH]; 6],
    /// Child references (meaningless in empty slots).
    pub child: [ChildRef; WIDTH],
}

impl Node {
    /// A node with every slot empty.
    pub const EMPTY: Node = Node {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [0; WIDTH],
    };

    /// Sets slot `i` to a child with bounds `[lo, hi]`.
    pub fn set(&mut self, i: usize, lo: Vec3, hi: Vec3, child: ChildRef) {
        for axis in 0..3 {
            self.bounds[2 * axis][i] = lo[axis];
            self.bounds[2 * axis + 1][i] = hi[axis];
        }
        self.child[i] = child;
    }
}

/// Four triangles, lane by lane: `v0`, `e1 = v1 − v0`, `e2 = v2 − v0` (x, y, z rows), and
/// their indices in the build input; 160 bytes, 32-byte aligned, so any packet lies in
/// exactly three cache lines. The normal e1 × e2 is recomputed by the
/// test (nine multiply-adds on four lanes) rather than stored: that keeps a packet in three
/// cache lines instead of four. Unused lanes hold a zero triangle (never hit: its normal
/// is zero).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct TriPacket {
    pub v0: [[f32; PACKET]; 3],
    pub e1: [[f32; PACKET]; 3],
    pub e2: [[f32; PACKET]; 3],
    pub prim: [u32; PACKET],
}

impl TriPacket {
    /// A packet of zero triangles.
    pub const EMPTY: TriPacket = TriPacket {
        v0: [[0.0; PACKET]; 3],
        e1: [[0.0; PACKET]; 3],
        e2: [[0.0; PACKET]; 3],
        prim: [u32::MAX; PACKET],
    };

    /// Puts triangle `t` (input index `prim`) in lane `lane`.
    pub fn set(&mut self, lane: usize, t: &[Vec3; 3], prim: u32) {
        let e1 = t[1] - t[0];
        let e2 = t[2] - t[0];
        for axis in 0..3 {
            self.v0[axis][lane] = t[0][axis];
            self.e1[axis][lane] = e1[axis];
            self.e2[axis][lane] = e2[axis];
        }
        self.prim[lane] = prim;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_leaf_encoding() {
        assert_eq!(std::mem::size_of::<Node>(), 256);
        assert_eq!(std::mem::size_of::<TriPacket>(), 160);
        for (start, count) in [(0, 1), (12345, 8), (MAX_PACKETS - 1, 3)] {
            let r = leaf_ref(start, count);
            assert!(is_leaf(r));
            assert_eq!(leaf_range(r), (start, count));
        }
        assert!(!is_leaf(12345));
    }
}
