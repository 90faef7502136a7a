//! Stage 3: visibility — ray casting against all triangles of the scene.
//!
//! [`Bvh`] is our own bounding volume hierarchy (the article's BSP tree, modernised): an
//! 8-wide BVH built by binned SAH (Wald 2007, "On fast construction of SAH-based bounding
//! volume hierarchies"), traversed one ray at a time with SIMD box and triangle tests
//! (Wald, Benthin & Boulos 2008; Ernst & Greiner 2008), closest-hit and any-hit queries.
//! Pure-Rust BVH crates were measured 5–30× slower than Embree on incoherent rays here, so
//! this piece is ours; `radiosity bench rays` measures it against Embree on the same rays
//! (see BENCHMARKS.md).
//!
//! Robustness against self-intersection at shared edges is handled by the callers through
//! per-triangle ids: a visibility query between two surface points ignores the triangles of
//! the two polygons the points lie on (a planar polygon cannot block a ray that leaves it),
//! and starts/ends a relative epsilon away from them. See [`SceneRays`].

mod bvh;
mod prefetch;
mod scene_rays;
pub mod workload;

pub use bvh::{Bvh, BvhStats, Hit, Ray};
pub(crate) use prefetch::prefetch;
pub use scene_rays::{SceneRays, SEGMENT_EPS};
