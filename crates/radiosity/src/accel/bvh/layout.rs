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

/// Child reference: the [`Unit`] index of an interior node, or (top bit set) a leaf of
/// `1..=8` packets starting at a unit index.
pub(super) type ChildRef = u32;

const LEAF_BIT: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 28;
const START_MASK: u32 = (1 << COUNT_SHIFT) - 1;
/// The storage the leaf encoding can address, in units (2²⁸ units: 8 GiB, ~2·10⁸ triangles).
pub(super) const MAX_UNITS: usize = START_MASK as usize + 1;

#[inline(always)]
pub(super) fn is_leaf(r: ChildRef) -> bool {
    r & LEAF_BIT != 0
}

/// A leaf reference to `count` (1..=8) packets from `start`.
#[inline]
pub(super) fn leaf_ref(start: usize, count: usize) -> ChildRef {
    debug_assert!((1..=MAX_LEAF_PACKETS).contains(&count) && start < MAX_UNITS);
    LEAF_BIT | (((count - 1) as u32) << COUNT_SHIFT) | start as u32
}

/// (unit of the first packet, packet count) of a leaf reference.
#[inline(always)]
pub(super) fn leaf_range(r: ChildRef) -> (usize, usize) {
    ((r & START_MASK) as usize, (((r >> COUNT_SHIFT) & 7) + 1) as usize)
}

/// The storage of the whole tree: 32-byte units, nodes (7 units) each followed by the
/// packets of its leaf children (5 units each), depth first. Keeping a node and its leaves
/// side by side (as Embree's arena allocator does) puts them in the same pages and often
/// in lines the hardware prefetcher fetched with the node.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub(super) struct Unit(pub [f32; 8]);

/// Units per node.
pub(super) const NODE_UNITS: usize = 7;
/// Units per packet.
pub(super) const PACKET_UNITS: usize = 5;

/// A stored node: bounds rows 0–5, child references (as bits) in unit 6. 224 bytes.
pub(super) type NodeUnits = [Unit; NODE_UNITS];
/// A stored packet: rows v0x v0y v0z e1x e1y e1z e2x e2y e2z of four floats, then the
/// four input indices (as bits). 160 bytes.
pub(super) type PacketUnits = [Unit; PACKET_UNITS];

/// The node stored at unit `i`.
#[inline(always)]
pub(super) fn node_at(units: &[Unit], i: usize) -> &NodeUnits {
    units[i..i + NODE_UNITS].try_into().expect("exact length")
}

/// The packet stored at unit `i`.
#[inline(always)]
pub(super) fn packet_at(units: &[Unit], i: usize) -> &PacketUnits {
    units[i..i + PACKET_UNITS].try_into().expect("exact length")
}

/// Child reference `c` of a stored node.
#[inline(always)]
pub(super) fn child(n: &NodeUnits, c: usize) -> ChildRef {
    n[NODE_UNITS - 1].0[c].to_bits()
}

/// Row `k` (0–8: v0x v0y v0z e1x e1y e1z e2x e2y e2z) of a stored packet.
#[inline(always)]
pub(super) fn prow(p: &PacketUnits, k: usize) -> &[f32; PACKET] {
    let u = &p[k / 2].0;
    if k % 2 == 0 {
        u.first_chunk().expect("half")
    } else {
        u.last_chunk().expect("half")
    }
}

/// Input index of lane `l` of a stored packet.
#[inline(always)]
pub(super) fn prim(p: &PacketUnits, l: usize) -> u32 {
    p[PACKET_UNITS - 1].0[PACKET + l].to_bits()
}

/// An 8-wide node while building: children's bounds as rows `[lo_x, hi_x, lo_y, hi_y, lo_z,
/// hi_z]`, one lane per child, then the child references.
#[derive(Clone, Copy, Debug)]
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

    /// The stored form.
    pub fn to_units(self) -> NodeUnits {
        let mut u = [Unit::default(); NODE_UNITS];
        for (unit, row) in u.iter_mut().zip(self.bounds) {
            unit.0 = row;
        }
        u[6].0 = self.child.map(f32::from_bits);
        u
    }
}

/// Four triangles, lane by lane: `v0`, `e1 = v1 − v0`, `e2 = v2 − v0` (x, y, z rows), and
/// their indices in the build input; 160 bytes, 32-byte aligned, so any packet lies in
/// exactly three cache lines. The normal e1 × e2 is recomputed by the
/// test (nine multiply-adds on four lanes) rather than stored: that keeps a packet in three
/// cache lines instead of four. Unused lanes hold a zero triangle (never hit: its normal
/// is zero).
#[derive(Clone, Copy, Debug)]
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

    /// The stored form.
    pub fn to_units(self) -> PacketUnits {
        let rows = [self.v0, self.e1, self.e2];
        let mut u = [Unit::default(); PACKET_UNITS];
        for k in 0..9 {
            let row = rows[k / 3][k % 3];
            u[k / 2].0[4 * (k % 2)..4 * (k % 2) + 4].copy_from_slice(&row);
        }
        u[4].0[4..].copy_from_slice(&self.prim.map(f32::from_bits));
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_leaf_encoding() {
        assert_eq!(std::mem::size_of::<NodeUnits>(), 224);
        assert_eq!(std::mem::size_of::<PacketUnits>(), 160);
        for (start, count) in [(0, 1), (12345, 8), (MAX_UNITS - 1, 3)] {
            let r = leaf_ref(start, count);
            assert!(is_leaf(r));
            assert_eq!(leaf_range(r), (start, count));
        }
        assert!(!is_leaf(12345));
    }

    #[test]
    fn stored_forms_round_trip() {
        let mut n = Node::EMPTY;
        n.set(3, Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0), leaf_ref(77, 2));
        let u = n.to_units();
        assert_eq!(child(&u, 3), leaf_ref(77, 2));
        assert_eq!((u[0].0[3], u[1].0[3], u[2].0[3], u[3].0[3], u[4].0[3], u[5].0[3]), (1.0, 4.0, 2.0, 5.0, 3.0, 6.0));
        let mut p = TriPacket::EMPTY;
        p.set(2, &[Vec3::new(1.0, 2.0, 3.0), Vec3::new(2.0, 4.0, 6.0), Vec3::new(0.0, 0.0, 1.0)], 42);
        let u = p.to_units();
        let want = [1.0, 2.0, 3.0, 1.0, 2.0, 3.0, -1.0, -2.0, -2.0];
        for (k, w) in want.iter().enumerate() {
            assert_eq!(prow(&u, k)[2], *w, "row {k}");
        }
        assert_eq!((prim(&u, 2), prim(&u, 0)), (42, u32::MAX));
    }
}
