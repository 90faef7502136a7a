//! Stage 3: visibility — ray casting against all triangles of the scene.
//!
//! [`Bvh`] is our own bounding volume hierarchy (the article's BSP tree, modernised): a
//! binned SAH build (Wald 2007, "On fast construction of SAH-based bounding volume
//! hierarchies") and stack-based ordered traversal with closest-hit and any-hit queries.
//! Pure-Rust BVH crates were measured 5–30× slower than Embree on incoherent rays here, so
//! this piece is ours (see BENCHMARKS.md).
//!
//! Robustness against self-intersection at shared edges is handled by the callers through
//! per-triangle ids: a visibility query between two surface points ignores the triangles of
//! the two polygons the points lie on (a planar polygon cannot block a ray that leaves it),
//! and starts/ends a relative epsilon away from them. See [`SceneRays`].

pub mod bvh;
mod scene_rays;

pub use bvh::{Bvh, BvhStats, Hit, Ray};
pub use scene_rays::{SceneRays, SEGMENT_EPS};
