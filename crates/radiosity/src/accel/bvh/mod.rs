//! Our bounding volume hierarchy over triangles: f32, 8-wide, closest-hit and any-hit
//! single-ray queries with per-triangle filters.
//!
//! The method, file by file:
//! - `build.rs`: top-down binned SAH (Wald 2007, "On fast construction of SAH-based
//!   bounding volume hierarchies") building 8-wide nodes directly by repeatedly splitting
//!   the child of largest area, as Embree does (Wald, Woop, Benthin, Johnson & Ernst 2014);
//!   parallel with rayon.
//! - `layout.rs`: 224-byte nodes holding their eight children's boxes as a structure of
//!   arrays (Wald, Benthin & Boulos 2008; Ernst & Greiner 2008; Dammertz, Hanika & Keller
//!   2008), and leaves of 4-triangle packets for Möller–Trumbore, stored in one array with
//!   each node followed by its leaves.
//! - `traverse.rs`: ordered depth-first traversal with distance-tagged stack entries
//!   (closest hit) and unordered traversal with early exit (any hit).
//! - `kernel.rs`: the per-node box test (slab test made conservative as in Ize 2013) and the
//!   per-packet triangle test (Möller & Trumbore 1997, deferred division), portable Rust.
//! - `avx2.rs`: the same two tests with AVX2 intrinsics, chosen at run time when the CPU has
//!   AVX2; the only `unsafe` code of the library (see its docs for why it is sound).
//!
//! Woop, Benthin & Wald's watertight test (2013) was considered for the triangles and not
//! used: it costs a per-ray shear and three vertex transforms per triangle, and the callers
//! never depend on watertightness at shared edges (visibility queries ignore the two end
//! polygons; see `SceneRays`). The edge rule here counts edges as inside, so a ray through a
//! shared edge hits at least one of the two triangles up to rounding.
//!
//! Numbers against Embree on the project's scenes are in BENCHMARKS.md
//! (`radiosity bench rays`).

mod build;
mod kernel;
mod layout;
mod traverse;

#[cfg(target_arch = "x86_64")]
mod avx2;

#[cfg(test)]
mod tests;

use glam::Vec3;

use layout::Unit;

/// A ray with a parametric interval: hits count when `tmin < t < tmax`.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be normalised; t is in units of this vector).
    pub dir: Vec3,
    /// Hits at or before this are ignored.
    pub tmin: f32,
    /// Hits at or beyond this are ignored.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `(tmin, tmax)`.
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

/// Shape and expected cost of a hierarchy, in the terms Embree's statistics use.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Interior (8-wide) nodes.
    pub nodes: usize,
    /// Leaves.
    pub leaves: usize,
    /// Triangle packets (four lanes each).
    pub packets: usize,
    /// Mean children per node.
    pub children_per_node: f64,
    /// Mean triangles per leaf.
    pub triangles_per_leaf: f64,
    /// Deepest leaf, in nodes from the root.
    pub depth: usize,
    /// Surface-area cost of the nodes: Σ area(node) / area(root).
    pub sah_nodes: f64,
    /// Surface-area cost of the leaves: Σ area(leaf) · packets / area(root).
    pub sah_leaves: f64,
}

/// The hierarchy.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    /// Nodes and leaf packets, the root node first; empty when there is nothing to hit.
    units: Vec<Unit>,
    /// Interior nodes stored.
    nodes: usize,
    /// Triangles in the build input (non-finite ones included).
    len: usize,
    /// Present when the CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    avx2: Option<avx2::Avx2>,
}

impl Bvh {
    /// Builds the hierarchy over `tris` (each three vertices). Degenerate triangles are
    /// kept (they are never hit); triangles with a non-finite coordinate are left out.
    pub fn build(tris: &[[Vec3; 3]]) -> Bvh {
        let (units, nodes) = build::build(tris);
        Bvh {
            units,
            nodes,
            len: tris.len(),
            #[cfg(target_arch = "x86_64")]
            avx2: avx2::Avx2::detect(),
        }
    }

    /// Number of triangles in the build input.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when built over no triangles.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of (8-wide) nodes, for statistics.
    pub fn node_count(&self) -> usize {
        self.nodes
    }

    /// Memory used by nodes and triangle packets, in bytes.
    pub fn memory_bytes(&self) -> usize {
        self.units.len() * std::mem::size_of::<Unit>()
    }

    /// Shape statistics and SAH cost (for benchmarks and tuning).
    pub fn stats(&self) -> BvhStats {
        let mut s = BvhStats::default();
        if self.units.is_empty() {
            return s;
        }
        let half_area = |n: &layout::NodeUnits, i: usize| {
            let d = [0, 1, 2].map(|a| (n[2 * a + 1].0[i] - n[2 * a].0[i]).max(0.0) as f64);
            d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
        };
        let root = layout::node_at(&self.units, 0);
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for a in 0..3 {
            for i in 0..layout::WIDTH {
                lo[a] = lo[a].min(root[2 * a].0[i]);
                hi[a] = hi[a].max(root[2 * a + 1].0[i]);
            }
        }
        let d = [0, 1, 2].map(|a| (hi[a] - lo[a]).max(0.0) as f64);
        let root_area = (d[0] * d[1] + d[1] * d[2] + d[2] * d[0]).max(f64::MIN_POSITIVE);
        let mut children = 0;
        let mut tris = 0;
        s.sah_nodes = 1.0;
        let mut stack = vec![(0u32, 1usize)];
        while let Some((ni, depth)) = stack.pop() {
            s.nodes += 1;
            let n = layout::node_at(&self.units, ni as usize);
            for i in 0..layout::WIDTH {
                if n[0].0[i] > n[1].0[i] {
                    continue;
                }
                children += 1;
                let area = half_area(n, i) / root_area;
                let c = layout::child(n, i);
                if layout::is_leaf(c) {
                    let (start, count) = layout::leaf_range(c);
                    s.leaves += 1;
                    s.packets += count;
                    s.depth = s.depth.max(depth);
                    s.sah_leaves += area * count as f64;
                    tris += (0..count)
                        .map(|k| {
                            let p = layout::packet_at(&self.units, start + k * layout::PACKET_UNITS);
                            (0..layout::PACKET).filter(|&l| layout::prim(p, l) != u32::MAX).count()
                        })
                        .sum::<usize>();
                } else {
                    s.sah_nodes += area;
                    stack.push((c, depth + 1));
                }
            }
        }
        s.children_per_node = children as f64 / s.nodes as f64;
        s.triangles_per_leaf = tris as f64 / s.leaves.max(1) as f64;
        s
    }

    /// Closest hit along the ray.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.intersect_filtered(ray, |_| false)
    }

    /// Closest hit, ignoring triangles for which `skip(prim)` is true.
    #[inline]
    pub fn intersect_filtered(&self, ray: &Ray, skip: impl Fn(u32) -> bool) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if let Some(k) = self.avx2 {
            return avx2::closest(k, self, ray, skip);
        }
        traverse::closest(kernel::Portable, self, ray, skip)
    }

    /// True if anything is hit within `(tmin, tmax)`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_filtered(ray, |_| false)
    }

    /// True if a triangle with `skip(prim) == false` is hit within `(tmin, tmax)`.
    #[inline]
    pub fn occluded_filtered(&self, ray: &Ray, skip: impl Fn(u32) -> bool) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some(k) = self.avx2 {
            return avx2::occluded(k, self, ray, skip);
        }
        traverse::occluded(kernel::Portable, self, ray, skip)
    }
}
