//! # radiosity
//!
//! The finite-element method for light transfer between diffuse surfaces. The data flows
//! one way through the pipeline, one module per stage:
//!
//! ```text
//! scene file ──scene::load──▶ SceneDesc ──Scene::from_desc──▶ Scene ──mesh──▶ Mesh ──▶ accel::Bvh
//!   ──form_factor──▶ transport::Transport ──solve──▶ radiosity per element (+ SolveStats)
//!   ──reconstruct──▶ radiosity per vertex ──render──▶ Image ──output──▶ PNG · EXR · report
//! ```
//!
//! Units: linear radiometric quantities everywhere. Radiosity `B` (exitance) in W/m² (or
//! the scene's own units) per RGB channel; an emitter's `Ke` is emitted **radiance** `L_e`,
//! so its emitted exitance is `E = π·L_e`; an image pixel on a diffuse surface holds
//! `L = B/π`. Tone mapping happens only in [`output`].
//!
//! The library never prints and never exits: errors are typed ([`Error`], with file:line for
//! input errors), progress and cancellation go through [`progress::Progress`].
//!
//! ## The public API (what the CLI, the Python package and `examples/` call)
//!
//! - load a scene: [`scene::load_scene`] (OBJ, glTF, TOML, .vs3, built-in names), or
//!   [`scene::Scene::from_desc`] on a [`scene::SceneDesc`] built in code
//!   ([`scene::arrays::scene_from_arrays`] from vertex/face arrays);
//! - choose methods: [`form_factor::Method`] and [`form_factor::Options`], [`solve::Solver`],
//!   [`transport::Kind`], gathered in [`pipeline::Settings`];
//! - solve: [`pipeline::solve_scene`] (per-element radiosity, per-object means, the report),
//!   [`pipeline::solve_all`] (every solver on one mesh and F); render with [`render`];
//! - matrices: [`view_factors::compute`] / [`view_factors::Job`] (per object or element,
//!   with diagnostics), single factors [`form_factor::analytic::form_factor`] and
//!   [`form_factor::analytic::point_factor`];
//! - heat: [`thermal::solve`] (per surface T, q, Q, J, G; grey or in wavelength bands),
//!   [`thermal::exchange_factors`] (Gebhart factors, conductances).
//!
//! Internals stay inside the crate: the BVH's nodes and traversal (only [`accel::Bvh`],
//! [`accel::SceneRays`] and their rays are public), the contour-integral kernel, and the
//! random sampling streams.
#![warn(missing_docs)]
// `unsafe` only in `accel::bvh::avx2` (SIMD intrinsics behind run-time detection; see there).
#![deny(unsafe_code)]

pub mod accel;
pub mod back_faces;
pub mod direct;
pub mod error;
pub mod form_factor;
pub mod geom;
pub mod lights;
pub mod mesh;
pub mod output;
pub mod pipeline;
pub mod progress;
pub mod reconstruct;
pub mod render;
pub mod report;
pub(crate) mod sampling;
pub mod scene;
pub mod sky;
pub mod solve;
pub mod thermal;
pub mod transport;
pub mod view_factors;

pub use error::{Error, Location, Result, Warning};
pub use progress::{NoProgress, Progress};

/// A linear RGB triple (radiance, radiosity, reflectance ...); the unit is given where used.
pub type Rgb = glam::DVec3;

/// Luminance of a linear Rec.709/sRGB colour (used for picking shooters, metrics).
#[inline]
pub fn luminance(c: Rgb) -> f64 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}
