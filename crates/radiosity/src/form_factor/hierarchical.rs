//! Hierarchical links with clustering: which node pairs exchange light, and their factors
//! (Hanrahan, Salzman & Aupperle 1991, "A rapid hierarchical radiosity algorithm"; clusters
//! after Smits, Arvo & Greenberg 1994 and Sillion 1995).
//!
//! The top nodes of the element tree ([`Tree`]) holding at most 1/256 of the elements
//! (clusters or surface nodes; only surface nodes without [`Options::cluster_receivers`])
//! start linked to the root, one parallel task each, and each pair `(R, S)` is refined
//! recursively:
//!
//! - pairs that cannot exchange light are dropped: `S` inside `R`'s plane or behind it, `R`
//!   behind a surface node `S`; a node holding the other is opened;
//! - the factor `F_RS` is estimated from a few points of `R` (its receiver points or, above
//!   the leaves, the centroids of a [`Tree::frontier`]) against a frontier of up to eight
//!   nodes of `S`: exact contour integrals ([`super::analytic::point_factor`]) for nearby elements,
//!   `cosθ_R · P_S(−d) / (π r² + P_S(−d))` otherwise (a disk of the node's projected area,
//!   bounded near it), with `P_S` the orientation-aware projected area of a cluster
//!   ([`crate::transport::hierarchical::Tree::projected_area`]);
//! - the link is accepted when the pair is well separated, `(size_R + size_S) / r < θ`
//!   (`separation`), and its visibility, from `visibility_rays` rays between area-uniform
//!   points of the two nodes (half as many for links below the power tolerance), is not
//!   partial — or it is, but the link's power `ρ_R · F_RS · A_R · B̂_S` is below
//!   `tolerance × Σ A B̂` (BF refinement; `B̂` = emission + an ambient estimate, plus each
//!   element's first bounce `ρ·D·E` where the direct columns `D` are known): partial
//!   links that matter are refined, so shadow boundaries get fine links. A link above
//!   the tolerance that every ray found hidden takes a second look, up to [`GLIMPSE`] ×
//!   as many rays by its power, before it is dropped: light through a slit (the
//!   ceiling's spot above a lamp 1 cm under it, seen past the lamp's edge) has a visible
//!   share that 8 rays miss, and its links were lost. With the first
//!   bounce known, a surface source's ray ends are drawn by `A·B̂` instead of by area: the
//!   visibility is that of its light (a ceiling 0.01 above a lamp's back side holds most
//!   of its node's light in a spot the lamp hides from the room; read by area, its links
//!   carried that light past the lamp, and RenderPark's closed cube `--two-sided` created
//!   2 % of its light, a small copy of it 5–6 %); so are a cluster source's, by its
//!   exposed faces' `A·B̂` for a far pair (its reading weighs its faces by projected area,
//!   so a spot hidden from the receiver was read in full: the cube created 0.8 %, now
//!   0.16 %). (Widening θ for
//!   low-power links, as BF refinement also allows, was measured: up to 2× halved the links
//!   on the classroom but biased it 2.5 % dark);
//! - the factor varies across a large receiver: each link carries its gradient (a plane
//!   fitted through the estimates at the receiver's points, limited so that it cannot
//!   exceed the mean), and the push evaluates the ancestors' irradiance at each child's
//!   centroid (first-order push: row sums in the furnace within ±0.5 % instead of ±6 % at
//!   θ = 0.5);
//! - a cluster's radiosity is read as seen from the receiver
//!   ([`crate::transport::hierarchical::Link::directional`]); clusters whose elements emit
//!   unequally (a lamp and its housing) are never sources;
//! - a cluster receiver takes links from sources that emit nothing, only when they are
//!   fully visible or fully hidden (a partly visible pair is split whatever its power: the
//!   cluster's parts may hide each other), as irradiance per unit
//!   cosine from one direction, spread to its elements by their normals
//!   ([`crate::transport::hierarchical::DIR_BIN_SIDE`]); light from concentrated emitters
//!   (emitting elements on under a quarter of the area) always reaches surface nodes
//!   (exact cosine). Under emission spread over the scene (a furnace) clusters take it too:
//!   else every cluster is split to its surfaces (the conference room in a furnace had not
//!   finished its links after 17 CPU minutes; now 25 s);
//! - otherwise the larger node is split — but not a leaf, nor a node at the *minimum size*
//!   ([`Options::min_size`], Hanrahan et al.'s `A_ε`: bounding-box diagonal or √area at
//!   most the size): two such nodes are linked as they are, separated or not, their factor
//!   integrated point by point with visibility ([`Ctx::terminal_factor`]). This bounds
//!   the links by the scene's area rather than its polygon count: a chair of 500 triangles
//!   exchanges light with the room as one cluster. Near the minimum size BF refinement
//!   also stops the split: a pair of nodes at most [`Options::coarse_size`] × the minimum
//!   size, not well separated but not close (ratio below [`COARSE_SEPARATION`] × θ), whose
//!   estimated link carries at most the tolerance is linked as it stands, integrated
//!   like a terminal link (`Ctx::coarse`). Without it every such pair goes down to the
//!   minimum size, and the links grow as the square of the nodes at that size (Sponza:
//!   12.7 M links on 4 765 such nodes; 4.25 M with it).
//!
//! Emitted light needs no links when the emitting elements are few
//! ([`Options::direct_columns`]): every element gets point-sampled factors to each of them
//! it may see (exact cosine, shadow rays; groups of emitters it cannot see — behind it,
//! facing away, or far with every test ray blocked — are skipped whole by walking a tree
//! over the emitters, `super::emitter_tree`, so a building's rooms do not test each other's
//! lamps), stored as sparse rows beside the links, and emitting nodes are no sources in
//! the refinement. The links then carry only reflected light, which
//! varies slowly, and the cost of the refinement does not depend on the lights.
//!
//! Before the links, every element casts [`Options::closure_rays`] rays over its
//! cosine-weighted hemisphere. They measure two things:
//!
//! - its *exposure*, the share of rays that meet nothing within the minimum size, or the
//!   mesh size when links go down to the elements (the *reach*, `exposure_reach`;
//!   [`crate::transport::hierarchical::Tree::set_exposure`]). A cluster sends to
//!   and receives from nodes beyond the reach (boxes farther apart, *far* links) through its
//!   exposed faces only: its projected area, its directional reading and the share of
//!   arriving light each face takes are weighted by exposure. Faces inside a closed slab,
//!   the back copy of a wall facing a cavity, a seat under a desk top, face far nodes but
//!   can neither see them nor be seen: spread by normal alone, they soaked up a cluster's
//!   light (the conference room's back faces held twice the power a stochastic solve gives
//!   them) and darkened its reading (the ceiling read chairs and tables 14 % too dark, by
//!   Monte Carlo against the same solution; `link_truth` in the tests). Near links (boxes
//!   within the reach) reach every face, their factors integrated with rays;
//! - its *closure*, the fraction of rays whose first hit is a front face. What its links
//!   bring is fitted to it ([`crate::transport::hierarchical::Closure`]): coarse links
//!   between nodes that touch are biased low beside a shared edge, the rays are not
//!   (without the fit 13.5 % of the conference room's light went missing). An element
//!   whose rays all met a surface is fitted to its expected closure, not to one
//!   ([`crate::transport::hierarchical::CLOSED_PRIOR`]). A row still far
//!   short of its closure after the fit (below the lower end of its Wilson interval at
//!   `RAY_ROW_Z`, or scaled by the largest factor the fit allows: a face a few units from
//!   a wall, behind a mounted board, that no link reaches from its side) is traced instead: `RAY_ROW_FACTOR` × as many rays, the share of
//!   them landing on each element its factor (Monte Carlo form factors;
//!   [`crate::transport::Hierarchy::set_ray_rows`], which fits the other rows again without
//!   them), where emitted light goes through the direct columns or is spread (rays find
//!   concentrated lights poorly). In the conference
//!   room in a furnace this took the elements off by more than 1 % from 262 598 to 57 040.
//!
//! Two elements (a leaf–leaf link, or an element's factor to an emitting element in the
//! direct columns) take the point-sampled factor of [`super::point_sampled`]'s kernel: the
//! contour integral at area-uniform random points of the receiver's open part (1, 4 or 9 of
//! them, stratified, more when close) times the visible fraction of `visibility_samples²`
//! rays. Random rather than the fixed receiver points: a contact shadow lies at an
//! element's edge beside its occluder, away from every fixed point, so fixed points
//! over-read the light there (`Ctx::leaf_factor`). Each task draws from its own random
//! stream, so the links do not depend on the thread count. [`predict_memory`] is checked
//! before the coverage test and the links.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::accel::SceneRays;
use super::emitter_tree::EmitterTree;
use crate::geom::{self, kernel::point_to_polygon};
use crate::mesh::{Mesh, Receivers};
use crate::sampling::{rng_for, stratified, Rng};
use crate::transport::hierarchical::{Closure, Exclusion, Hierarchy, HierarchyStats, Link, Node, Tree, NONE};
use crate::{Error, Progress, Result, Rgb};

/// Link refinement settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// A link is accepted when `(size_R + size_S) / distance` is below this.
    pub separation: f64,
    /// Partially visible links carrying less than this fraction of the scene's total power
    /// are kept rather than refined (BF refinement).
    pub tolerance: f64,
    /// Rays per link above the leaves that classify its visibility (full, none, partial).
    pub visibility_rays: usize,
    /// Clusters may receive (links from non-emitting sources to groups of elements in
    /// several planes, spread to them by their normals); off: only surface nodes receive.
    pub cluster_receivers: bool,
    /// Nodes whose bounding-box diagonal is at most this (scene units) are not split to
    /// refine a link (Hanrahan et al.'s `A_ε`): two such nodes that are not well separated
    /// are linked as they are. 0: refine down to the elements. The pipeline sets it to
    /// twice the mesh size above 50 000 elements when it is `None`
    /// (`crate::pipeline::link_min_size`), so the elements of large surfaces stay leaves while a
    /// chair's many small polygons exchange light with the room as a whole ([`link`] alone
    /// takes `None` as 0).
    pub min_size: Option<f64>,
    /// Light leaving emitting elements reaches every element through exact per-element
    /// factors ([`DirectColumns`]) when the scene has few emitters (at most
    /// [`DIRECT_MAX_EMITTERS`] emitting elements, and at most 1/16 of all); the links then
    /// carry only reflected light. Off: emitters are sources in the hierarchy like any node.
    pub direct_columns: bool,
    /// Rays per element that measure its closure, the fraction of its hemisphere that
    /// meets a front face; what its links bring is scaled to close the row to it (see
    /// [`crate::transport::Hierarchy::from_parts`]). 0: no closure fit. `None`:
    /// [`default_closure_rays`] for the minimum size.
    pub closure_rays: Option<usize>,
    /// BF refinement near the minimum size: a pair of nodes at most this many times the
    /// minimum size that is not well separated (but not closer than
    /// [`COARSE_SEPARATION`] × the separation allows), whose link carries at most
    /// `tolerance` × the scene's total power, is linked as it stands with a factor
    /// integrated point by point, not split down to the minimum size. 0: every such pair is split. No effect where links
    /// go down to the elements (minimum size 0).
    pub coarse_size: f64,
}

/// Elements per group whose closure rays are pooled (see [`Closure`]).
pub const CLOSURE_GROUP: usize = 16;

/// Default [`Options::closure_rays`] where links stop at a minimum size (above
/// 50 000 elements by default): there the rays are a large part of the links' cost
/// (conference room: 2.6 s at 16, 8.2 s at 64, the image and energy balance unchanged).
pub const DEFAULT_CLOSURE_RAYS: usize = 16;

/// Default [`Options::closure_rays`] where links go down to the elements (minimum size
/// 0): there the closure fit's ray noise is most of what varies between seeds, and the
/// rays cost little beside the links. Office2 per-object median error over seeds 0–7:
/// 2.02 % at 16, 1.79 % at 32, 1.63 % at 64, 1.70 % at 128 (rows: 1.71 %); classroom
/// over seeds 0–3: 2.38 % → 2.29 %, 0.03 → 0.10 s (BENCHMARKS.md, "Eleventh round").
pub const DEFAULT_CLOSURE_RAYS_TO_ELEMENTS: usize = 64;

/// The closure rays per element when none are given: [`DEFAULT_CLOSURE_RAYS_TO_ELEMENTS`]
/// for links refined down to the elements (`min_size` 0), else [`DEFAULT_CLOSURE_RAYS`].
pub fn default_closure_rays(min_size: f64) -> usize {
    if min_size > 0.0 {
        DEFAULT_CLOSURE_RAYS
    } else {
        DEFAULT_CLOSURE_RAYS_TO_ELEMENTS
    }
}

/// At most this many times [`Options::visibility_rays`] more rays test a link above the
/// power tolerance that every visibility ray found hidden, before it is dropped
/// ([`Ctx::glimpse`]): one ray that gets through makes it partial, and it is refined.
pub const GLIMPSE: usize = 32;

/// The second look's rays per unit of the link's unoccluded power over the tolerance
/// (between [`Options::visibility_rays`] and [`GLIMPSE`] times as many): a visible share
/// `p` that `N` rays all miss loses at most `power · p · (1 − p)^N ≤ power / (e N)`, here
/// under 1.2 % of the tolerance per link.
pub const GLIMPSE_PER_TOLERANCE: f64 = 32.0;

/// Elements per receiver group whose hidden emitters are culled together before each
/// element's own walk (see `super::emitter_tree`).
const RECEIVER_GROUP: usize = 64;

/// Most emitting elements for [`Options::direct_columns`]. Each receiver walks a tree over
/// them and skips the groups it cannot see (`super::emitter_tree`), so the cost follows the
/// emitters each element sees, not their number (it was 4 096 when every receiver tested
/// every emitter: the classroom tiled 7 × 7, 4 704 lamp elements, fell back to linking its
/// lamps and doubled its links per element).
pub const DIRECT_MAX_EMITTERS: usize = 65_536;

/// Direct-column entries per element assumed by [`predict_memory`] when the scene has more
/// emitting elements than this: measured 23 per element on the classroom (96 lamp
/// elements) and on the same room tiled 4 × 4 (1 536), each element seeing only its room's
/// lamps. A hall whose every element sees more lamp elements than this is under-predicted.
pub const PREDICTED_DIRECT_PER_ELEMENT: u64 = 256;

/// Default [`Options::separation`].
pub const DEFAULT_SEPARATION: f64 = 0.5;
/// Default [`Options::tolerance`].
pub const DEFAULT_TOLERANCE: f64 = 1e-6;
/// Default [`Options::visibility_rays`].
pub const DEFAULT_VISIBILITY_RAYS: usize = 8;

/// Default [`Options::coarse_size`]. Sponza under the sky (4 765 nodes at its minimum
/// size, 2.31): links 12.7 M → 4.25 M, the solve's links and products about half the time,
/// per-object median 4.51 → 4.50 %, courtyard image 3.28 → 3.26 %; the conference room
/// 1.32 M → 0.69 M links, escaped −0.55 → −0.12 % (less light created), image 3.63 → 3.72 %
/// (BENCHMARKS.md, "Fourteenth round"). At 2 it links little (Sponza 11.0 M).
pub const DEFAULT_COARSE_SIZE: f64 = 4.0;

/// [`Options::coarse_size`] applies to pairs whose separation ratio is below this many
/// times the separation (2.0 at the default 0.5): closer pairs (touching, overlapping)
/// are split down to the minimum size whatever their power.
pub const COARSE_SEPARATION: f64 = 4.0;

impl Default for Options {
    fn default() -> Self {
        Options {
            separation: DEFAULT_SEPARATION,
            tolerance: DEFAULT_TOLERANCE,
            visibility_rays: DEFAULT_VISIBILITY_RAYS,
            cluster_receivers: true,
            min_size: None,
            direct_columns: true,
            closure_rays: None,
            coarse_size: DEFAULT_COARSE_SIZE,
        }
    }
}

impl Options {
    /// The command-line flags of the settings that differ from the defaults (for the
    /// message that says they do not apply to form-factor rows).
    pub fn changed_flags(&self) -> Vec<&'static str> {
        let d = Options::default();
        [
            (self.separation != d.separation, "--link-separation"),
            (self.tolerance != d.tolerance, "--link-tolerance"),
            (self.visibility_rays != d.visibility_rays, "--link-rays"),
            (self.cluster_receivers != d.cluster_receivers, "--no-cluster-receivers"),
            (self.min_size != d.min_size, "--link-min-size"),
            (self.direct_columns != d.direct_columns, "--emitters-in-links"),
            (self.closure_rays != d.closure_rays, "--link-closure-rays"),
            (self.coarse_size != d.coarse_size, "--link-coarse-size"),
        ]
        .into_iter()
        .filter_map(|(changed, flag)| changed.then_some(flag))
        .collect()
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        if !(self.separation > 0.0 && self.separation <= 4.0) {
            return Err(Error::Invalid(format!("link separation must be in (0, 4], got {}", self.separation)));
        }
        if !(self.tolerance >= 0.0 && self.tolerance < 1.0) {
            return Err(Error::Invalid(format!("link tolerance must be in [0, 1), got {}", self.tolerance)));
        }
        if let Some(m) = self.min_size.filter(|m| !(*m >= 0.0 && m.is_finite())) {
            return Err(Error::Invalid(format!("link minimum node size must be finite and ≥ 0, got {m}")));
        }
        if let Some(m) = self.closure_rays.filter(|m| *m > 1024) {
            return Err(Error::Invalid(format!("closure rays must be at most 1024, got {m}")));
        }
        if !(self.coarse_size >= 0.0 && self.coarse_size <= 1e6) {
            return Err(Error::Invalid(format!("link coarse size must be in [0, 1e6] (times the minimum size), got {}", self.coarse_size)));
        }
        if self.visibility_rays == 0 || self.visibility_rays > 1024 {
            return Err(Error::Invalid(format!("link visibility rays must be between 1 and 1024, got {}", self.visibility_rays)));
        }
        Ok(())
    }
}

/// Links per node that links can reach ([`link_nodes`]) assumed by [`predict_memory`] at
/// the default separation, with margin: measured 2026-12-02 at the default minimum size
/// (the mesh size) on the classroom (1.75 M links on 7 865 such nodes: 223) and the
/// conference room (5.25 M links on 17 597: 298); with the minimum size 0 every node
/// counts (classroom: 3.6 M links on 24 429, 148). It falls as 1/θ² with a larger
/// separation.
pub const PREDICTED_LINKS_PER_NODE: f64 = 400.0;

/// The nodes of `tree` that links can reach when no node at or below `min_size` is split:
/// the root and every child of a node that may be split.
pub fn link_nodes(tree: &Tree, min_size: f64) -> u64 {
    let nodes = &tree.nodes;
    let mut count = 0u64;
    let mut stack = if nodes.is_empty() { Vec::new() } else { vec![0u32] };
    while let Some(k) = stack.pop() {
        count += 1;
        let nd = &nodes[k as usize];
        if !nd.is_leaf() && nd.size() > min_size && nd.area as f64 > min_size * min_size {
            stack.extend(nd.child);
        }
    }
    count
}

/// Peak memory of the hierarchical operator on `tree` (built over the elements' full areas
/// before the coverage test; close enough for a bound) with links refined down to
/// `min_size` at `separation`: links (36 bytes each while the refinement tasks hold them,
/// then about 16 stored: source, factor and, where they exist, gradient or direction and a
/// cluster's reading), the tree and the solver's per-node buffers, the sample record of
/// every element, and direct columns to
/// `emitters` (at most [`PREDICTED_DIRECT_PER_ELEMENT`] per element). Checked against the
/// memory limit before the coverage test and links.
pub fn predict_memory(tree: &Tree, min_size: f64, separation: f64, emitters: u64) -> u64 {
    let links =
        PREDICTED_LINKS_PER_NODE * (DEFAULT_SEPARATION / separation).powi(2) * link_nodes(tree, min_size) as f64;
    let elements = tree.order.len() as f64;
    // Node + the product's pull/push buffers (312 bytes) + its two reading tables (256
    // bytes per source slot, at most one slot per node; Sponza: a third of the nodes).
    let node = std::mem::size_of::<Node>() as f64 + 600.0;
    let direct = if emitters as usize <= DIRECT_MAX_EMITTERS {
        emitters.min(PREDICTED_DIRECT_PER_ELEMENT) as f64 * elements * 8.0
    } else {
        0.0
    };
    // The links' sample records ([`Sample`]) live while the links are refined.
    let samples = elements * std::mem::size_of::<Sample>() as f64;
    (links * (36.0 + 16.0) + elements * 2.0 * node + samples + direct) as u64
}

/// Bytes per element that a hierarchical run holds beside the links ([`predict_memory`]) and
/// what it held before predicting (the scene, mesh, rays and tree): the receiver points of
/// the coverage test (up to 14 points per element, each in its own allocation), the closure
/// and exposure, the solver's vectors, the traced rows and the final gather's point
/// locator and the exclusions ([`crate::transport::hierarchical::Exclusion`]), with the
/// allocator's slack. The peak resident memory less those two came to 309 bytes per element
/// on the conference room and up to 1 130 on Sponza, whose links outnumber the links'
/// prediction (897 per link node against 400); on the classroom, office2 and the scaling
/// series the links' prediction alone is above the peak. Sponza's peak ranged over
/// 0.84–0.97 GB from run to run (BENCHMARKS.md, "Sixteenth round", "Seventeenth round").
pub const PREDICTED_RUN_BYTES_PER_ELEMENT: f64 = 1200.0;

/// A hierarchical run's peak resident memory, predicted before the coverage test and the
/// links ([`predict_peak`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PeakPrediction {
    /// Resident already when predicting (the process's own measure where the system gives
    /// one, [`crate::transport::resident_memory`]; else 0).
    pub resident: u64,
    /// The links, tree buffers, sample records and direct columns ([`predict_memory`]).
    pub links: u64,
    /// The rest of the run, [`PREDICTED_RUN_BYTES_PER_ELEMENT`] per element.
    pub run: u64,
}

impl PeakPrediction {
    /// The predicted peak.
    pub fn total(&self) -> u64 {
        self.resident.saturating_add(self.links).saturating_add(self.run)
    }
}

/// The peak resident memory of a hierarchical run on `tree`: what the process holds now
/// (`resident`), the links ([`predict_memory`]) and [`PREDICTED_RUN_BYTES_PER_ELEMENT`] per
/// element for the rest. Checked against `--memory-limit` before the coverage test.
pub fn predict_peak(tree: &Tree, min_size: f64, separation: f64, emitters: u64, resident: u64) -> PeakPrediction {
    PeakPrediction {
        resident,
        links: predict_memory(tree, min_size, separation, emitters),
        run: (PREDICTED_RUN_BYTES_PER_ELEMENT * tree.order.len() as f64) as u64,
    }
}

/// Share of the area below which emitting elements count as concentrated
/// (`Ctx::sharp`).
const SHARP_EMITTERS: f64 = 0.25;

/// Adds each element's first bounce `ρ_i Σ_j D_ij E_j` (max channel; `D` the direct
/// columns, exact factors to the emitting elements) to the leaves' estimated radiosity
/// `b_hat` and takes the nodes' area-weighted means again. BF refinement weighs a link by
/// its source's `B̂`: with emission and the scene's mean ambient light alone, a ceiling
/// 0.01 above a lamp's back side — as bright as the lamp's own reflection, hidden from
/// the room behind it — read as dim as the rest of the ceiling, so its links to the room
/// were kept whole, at the ceiling's mean visibility, and carried its light past the lamp
/// (RenderPark's closed cube `--two-sided` created 2 % of its light).
fn first_bounce_estimate(tree: &Tree, d: &crate::transport::SparseRows, reflectance: &[Rgb], emission: &[Rgb], mut b_hat: Vec<f32>) -> Vec<f32> {
    let nodes = &tree.nodes;
    for k in (0..nodes.len()).rev() {
        let nd = &nodes[k];
        if nd.is_leaf() {
            let e = tree.order[nd.first as usize] as usize;
            let bounce = reflectance[e] * d.gather_row(e, emission);
            b_hat[k] += bounce.max_element() as f32;
        } else {
            let (a, b) = (nd.child[0] as usize, nd.child[1] as usize);
            let (wa, wb) = (nodes[a].area, nodes[b].area);
            let w = (wa + wb).max(f32::MIN_POSITIVE);
            b_hat[k] = (b_hat[a] * wa + b_hat[b] * wb) / w;
        }
    }
    b_hat
}

/// Prefix sums of `A·B̂` over the elements in tree order (`b_hat` per node; see
/// [`Ctx::visibility`]), with `A` the exposed area (`Node::area_x`) when `exposed`.
fn light_prefix(tree: &Tree, b_hat: &[f32], exposed: bool) -> Vec<f64> {
    let mut p = Vec::with_capacity(tree.order.len() + 1);
    let mut acc = 0.0;
    p.push(acc);
    for &e in &tree.order {
        let leaf = tree.leaf_of[e as usize] as usize;
        let nd = &tree.nodes[leaf];
        let a = if exposed { nd.area_x } else { nd.area };
        acc += a as f64 * b_hat[leaf].max(0.0) as f64;
        p.push(acc);
    }
    p
}

/// The exposure's reach in units of the minimum size (see [`Ctx::near`]).
const EXPOSURE_REACH: f64 = 1.0;

/// The exposure's reach ([`Ctx::near`]): [`EXPOSURE_REACH`] × the minimum size, or, when
/// links refine down to the elements (minimum size 0), the mesh's target element size.
/// With a reach of 0 every face counted as exposed, and a cluster receiver handed its light
/// by normal alone to faces hidden inside it: on the classroom (12 230 elements, minimum
/// size 0) pairs of thin rails 2 cm apart, whose facing sides see mostly each other, came
/// out 50–100 % too bright (raw link sums up to 1.45) and the per-object median error was
/// 2.74 %; with the reach at the mesh size 2.36 %, worst object −15 % instead of +100 %, at
/// no cost in time; office2 2.65 % → 1.98 % (BENCHMARKS.md, "Tenth round").
fn exposure_reach(min_size: f64, mesh_size: f64) -> f64 {
    let size = if min_size > 0.0 { min_size } else { mesh_size };
    if size.is_finite() && size > 0.0 {
        EXPOSURE_REACH * size
    } else {
        0.0
    }
}

/// Nodes opened near one point by [`Ctx::unoccluded_at`].
const NEAR_BUDGET: usize = 16;

/// A terminal link whose rough power (`ρ_R · B̂_S · F̃ · A_R`, with `F̃` the unoccluded
/// estimate of [`Ctx::rough_power`], no rays) is below the link tolerance is integrated
/// from `1/QUICK_TERMINAL_SHARE` of the pairs of points; the others from all of them. A
/// building's links are mostly terminal pairs at the minimum size, each carrying far less
/// than the tolerance: their noise averages out over the thousands each element gathers.
/// The choice must not depend on the sampled factor itself: until 2026-12-06 the quick
/// estimate was drawn first and kept when *it* came out below the tolerance, so low draws
/// were kept and high ones drawn again, and terminal links came out low on average (a
/// classroom chair's links from the floor at minimum size 0.8: 64 % below Monte Carlo
/// gathering; 4 % with the choice made before any ray).
const QUICK_TERMINAL_SHARE: usize = 4;

/// Without an explicit memory limit, the links stop when the system's available memory
/// falls below this (bytes) while they are refined.
const MEMORY_FLOOR: u64 = 256 << 20;

/// Nodes [`Ctx::faces_behind`] visits at most for one link.
const BEHIND_VISITS: usize = 256;

/// Topmost faces of a cluster receiver above which [`Ctx::faces_behind`] does not examine
/// a terminal link from a cluster source.
const BEHIND_CLUSTER_FACES: usize = 16;

/// The share of a cluster receiver's link, handed out by normal, above which a face behind
/// the link's surface source is excluded from it ([`Ctx::behind_shares`]).
const BEHIND_SHARE: f64 = 0.01;

/// Source frontier size (far-field summary of a source node).
const SOURCE_FRONTIER: usize = 8;
/// Receiver frontier size (points of a receiver node above the leaves).
const RECEIVER_FRONTIER: usize = 4;

/// An element as the rays of [`Ctx::visibility`] and [`Ctx::terminal_factor_with`] sample
/// it: corners, normal and polygon in one record, in tree order ([`Tree::slot_at`]), so a
/// sample costs two cache lines instead of the element, its vertices and the order.
#[derive(Clone, Copy, Debug)]
#[repr(align(64))]
struct Sample {
    corners: [DVec3; 4],
    normal: DVec3,
    patch: u32,
    quad: bool,
}

impl Sample {
    fn of_tree(tree: &Tree, mesh: &Mesh) -> Vec<Sample> {
        tree.order
            .par_iter()
            .map(|&e| {
                let el = &mesh.elements[e as usize];
                let (corners, n) = el.corners(&mesh.positions);
                Sample { corners, normal: el.normal, patch: el.patch, quad: n == 4 }
            })
            .collect()
    }

    /// [`crate::mesh::Element::point`].
    #[inline]
    fn point(&self, u: f64, v: f64) -> DVec3 {
        crate::mesh::point_on(&self.corners, self.quad, u, v)
    }
}

struct Ctx<'a> {
    tree: &'a Tree,
    /// Every element's [`Sample`], in tree order.
    samples: Vec<Sample>,
    mesh: &'a Mesh,
    rays: &'a SceneRays,
    receivers: &'a Receivers,
    ff: &'a super::Options,
    opts: &'a Options,
    /// Per node: area-weighted mean of max-channel reflectance.
    rho: Vec<f32>,
    /// Per node: estimated radiosity (emission + ambient, plus the first bounce
    /// `ρ·D·E` once the direct columns `D` are known), max channel.
    b_hat: Vec<f32>,
    /// With the first bounce in `b_hat`: prefix sums of `A·B̂` over the elements in tree
    /// order, from which [`Ctx::visibility`] draws a surface source's points (and a cluster
    /// source's for a near pair).
    light_prefix: Option<Vec<f64>>,
    /// [`Ctx::light_prefix`] over exposed area (`area_x · B̂`): where a far cluster source's
    /// visibility rays start (its light towards far nodes).
    light_prefix_x: Option<Vec<f64>>,
    /// Per node: its elements emit unequally (such a cluster, e.g. a lamp with a dark
    /// housing, is never a source: its radiosity depends on direction more than the
    /// first-order directional reading follows).
    emits: Vec<bool>,
    /// Per node: some element emits.
    emits_any: Vec<bool>,
    /// Per node that emits unequally: where its emitting elements lie and face.
    lit: Vec<LitFaces>,
    /// Emission is concentrated (emitting elements cover under [`SHARP_EMITTERS`] of the
    /// area): then a node with an emitter never sends to a cluster receiver, since direct
    /// light needs surfaces to land on. Under emission spread over the scene (a furnace,
    /// a glowing wall) that rule would split every cluster down to its surfaces.
    sharp: bool,
    /// Power below which a link may be coarse.
    power_eps: f64,
    /// Distance below which a point counts as on a plane.
    eps: f64,
    /// The emitting elements, when their light goes through direct columns.
    direct: Option<Vec<u32>>,
    /// [`Options::min_size`] (0 for `None`).
    min_size: f64,
    /// Links between nodes nearer than this are near-field ([`Link::near`]); the reach of
    /// the exposure rays. 0 without exposure.
    reach: f64,
}

#[derive(Default)]
struct Counts {
    pairs: u64,
    partial: u64,
    rays: u64,
    /// Links between two nodes at the minimum size, not well separated.
    terminal: u64,
    /// Pairs integrated where they stand by BF refinement near the minimum size
    /// (`Ctx::coarse`).
    coarse: u64,
    /// Links that every visibility ray found hidden and a second look found partial
    /// (`Ctx::glimpse`).
    glimpsed: u64,
}

/// Links every maximal surface node of `tree` against the whole tree; returns the
/// operator and the rays cast.
#[allow(clippy::too_many_arguments)]
pub fn link(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    tree: Tree,
    reflectance: &[Rgb],
    emission: &[Rgb],
    ff: &super::Options,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<(Hierarchy, u64)> {
    opts.validate()?;
    let n = mesh.len();
    let mut tree = tree;
    let stopped = AtomicBool::new(false);
    let total_rays = AtomicU64::new(0);
    let min_size = opts.min_size.unwrap_or(0.0);
    let closure_rays = opts.closure_rays.unwrap_or_else(|| default_closure_rays(min_size));
    let reach = if closure_rays > 0 { exposure_reach(min_size, mesh.target_size) } else { 0.0 };
    let (lo, hi) = geom::bounds_3d(&mesh.positions);
    // Distance below which a point counts as on a plane.
    let eps = 1e-7 * (hi - lo).length().max(f64::MIN_POSITIVE);
    // Closure and exposure first: the exposure shapes how clusters send and receive.
    let closure = if closure_rays > 0 {
        let t = &tree;
        let c = per_element(n, "closure", progress, &stopped, (f32::NAN, 1.0f32), |i| {
            let (c, o, rays) = closure(t, mesh, rays, receivers, ff.seed, closure_rays, eps, reach, i as usize);
            total_rays.fetch_add(rays, Ordering::Relaxed);
            (c, o)
        })?;
        let exposure: Vec<f32> = c.iter().map(|x| x.1).collect();
        tree.set_exposure(&exposure);
        Some(c.into_iter().map(|x| x.0).collect::<Vec<f32>>())
    } else {
        None
    };
    let nodes = &tree.nodes;
    // B̂ = E + ambient (progressive radiosity's estimate, Cohen et al. 1988).
    let area: f64 = nodes.first().map_or(0.0, |r| r.area as f64);
    let mut rho_mean = 0.0;
    let (mut emitted, mut emitting_area) = (0.0, 0.0);
    for k in 0..n {
        let a = (tree.area_prefix[k + 1] - tree.area_prefix[k]).max(0.0);
        let e = tree.order[k] as usize;
        rho_mean += a * reflectance[e].max_element();
        emitted += a * emission[e].max_element();
        if emission[e].max_element() > 0.0 {
            emitting_area += a;
        }
    }
    let rho_mean = if area > 0.0 { (rho_mean / area).min(0.999) } else { 0.0 };
    let ambient = if area > 0.0 { emitted / area * rho_mean / (1.0 - rho_mean) } else { 0.0 };
    let mut rho = vec![0f32; nodes.len()];
    let mut b_hat = vec![0f32; nodes.len()];
    let mut emits = vec![false; nodes.len()];
    let mut e_range = vec![(f32::INFINITY, f32::NEG_INFINITY); nodes.len()];
    for k in (0..nodes.len()).rev() {
        let nd = &nodes[k];
        if nd.is_leaf() {
            let e = tree.order[nd.first as usize] as usize;
            rho[k] = reflectance[e].max_element() as f32;
            b_hat[k] = (emission[e].max_element() + ambient) as f32;
            let x = emission[e].max_element() as f32;
            e_range[k] = (x, x);
        } else {
            let (a, b) = (nd.child[0] as usize, nd.child[1] as usize);
            let (wa, wb) = (nodes[a].area, nodes[b].area);
            let w = (wa + wb).max(f32::MIN_POSITIVE);
            rho[k] = (rho[a] * wa + rho[b] * wb) / w;
            b_hat[k] = (b_hat[a] * wa + b_hat[b] * wb) / w;
            e_range[k] = (e_range[a].0.min(e_range[b].0), e_range[a].1.max(e_range[b].1));
            emits[k] = e_range[k].1 > 1.001 * e_range[k].0;
        }
    }
    let total_power = (emitted + ambient * area).max(f64::MIN_POSITIVE);
    // Few emitters: their light goes to every element through exact factors.
    let emitting: Vec<u32> = (0..n as u32)
        .filter(|&e| emission[e as usize].max_element() > 0.0 && nodes[tree.leaf_of[e as usize] as usize].area > 0.0)
        .collect();
    let direct = (opts.direct_columns
        && !emitting.is_empty()
        && emitting.len() <= DIRECT_MAX_EMITTERS
        && emitting.len() * 16 <= n)
        .then_some(emitting);
    let mut ctx = Ctx {
        samples: Sample::of_tree(&tree, mesh),
        tree: &tree,
        mesh,
        rays,
        receivers,
        ff,
        opts,
        rho,
        b_hat,
        light_prefix: None,
        light_prefix_x: None,
        emits_any: e_range.iter().map(|r| r.1 > 0.0).collect(),
        sharp: emitting_area < SHARP_EMITTERS * area,
        lit: LitFaces::of_nodes(&tree, emission, &emits),
        emits,
        power_eps: opts.tolerance * total_power,
        eps,
        direct,
        min_size: opts.min_size.unwrap_or(0.0),
        reach,
    };
    let rays_before_direct = total_rays.load(Ordering::Relaxed);
    let direct_rows = match &ctx.direct {
        Some(em) => Some(ctx.direct_columns(em, progress, &stopped, &total_rays)?),
        None => None,
    };
    let direct_rays = total_rays.load(Ordering::Relaxed) - rays_before_direct;
    if let Some(d) = &direct_rows {
        ctx.b_hat = first_bounce_estimate(&tree, d, reflectance, emission, std::mem::take(&mut ctx.b_hat));
        ctx.light_prefix = Some(light_prefix(&tree, &ctx.b_hat, false));
        ctx.light_prefix_x = Some(light_prefix(&tree, &ctx.b_hat, true));
    }
    // Starting receivers: maximal surface nodes, split further so that no task holds more
    // than 1/256 of the elements (work for every thread).
    let max_count = (n / 256).max(64) as u32;
    let mut roots = Vec::new();
    let mut stack = if nodes.is_empty() { Vec::new() } else { vec![0u32] };
    while let Some(k) = stack.pop() {
        let nd = &nodes[k as usize];
        if (nd.surface || opts.cluster_receivers) && (nd.count <= max_count || nd.is_leaf()) {
            roots.push(k);
        } else {
            stack.extend(nd.child);
        }
    }
    roots.sort_unstable();
    // The run's memory limit, watched while the links grow (the peak checked before the
    // work is a prediction): before each task, the process's resident memory against an
    // explicit limit; without one, the system's available memory against
    // [`MEMORY_FLOOR`] (re-read each time: other work may free or take memory meanwhile).
    let limit = ff.memory_limit;
    let over = AtomicU64::new(0);
    progress.begin("links", roots.len() as u64);
    let results: Vec<(Vec<Link>, Vec<Exclusion>, Counts)> = roots
        .par_iter()
        .map(|&r| {
            if stopped.load(Ordering::Relaxed) || progress.should_stop() {
                stopped.store(true, Ordering::Relaxed);
                return (Vec::new(), Vec::new(), Counts::default());
            }
            let exceeded = match limit {
                Some(l) => crate::transport::resident_memory().filter(|&held| held > l),
                None => crate::transport::available_memory()
                    .filter(|&a| a < MEMORY_FLOOR)
                    .map(|_| crate::transport::resident_memory().unwrap_or(1)),
            };
            if let Some(held) = exceeded {
                over.fetch_max(held.max(1), Ordering::Relaxed);
                stopped.store(true, Ordering::Relaxed);
                return (Vec::new(), Vec::new(), Counts::default());
            }
            let (mut links, mut exclusions) = (Vec::new(), Vec::new());
            let mut counts = Counts::default();
            ctx.refine_root(r, &mut links, &mut exclusions, &mut counts);
            total_rays.fetch_add(counts.rays, Ordering::Relaxed);
            progress.advance(1);
            (links, exclusions, counts)
        })
        .collect();
    progress.end();
    let held = over.load(Ordering::Relaxed);
    if held > 0 {
        return Err(Error::TooLarge {
            what: match limit {
                Some(_) => format!("the hierarchical links of {n} elements (the process's resident memory passed the limit while they were refined)"),
                None => format!(
                    "the hierarchical links of {n} elements (the system's available memory fell below {} MiB while they were refined)",
                    MEMORY_FLOOR >> 20
                ),
            },
            needed: held,
            limit: limit.unwrap_or(held),
            hint: "use a larger --mesh-size, --link-min-size or --link-separation, or raise --memory-limit".into(),
        });
    }
    if stopped.load(Ordering::Relaxed) {
        return Err(Error::Cancelled);
    }
    let closure = if let Some(c) = closure {
        // Groups: the nodes that are not split (at the minimum size), or that hold at most
        // CLOSURE_GROUP elements: a few hundred rays each, where one element's 16 cannot
        // tell a row sum of 0.9 from 1.
        let mut group = vec![0u32; n];
        let mut stack = if n == 0 { Vec::new() } else { vec![0u32] };
        let mut next = 0u32;
        while let Some(k) = stack.pop() {
            let nd = ctx.node(k);
            if ctx.splittable(k) && nd.count as usize > CLOSURE_GROUP {
                stack.extend(nd.child);
                continue;
            }
            for slot in nd.first..nd.first + nd.count {
                group[tree.order[slot as usize] as usize] = next;
            }
            next += 1;
        }
        Some(Closure { fraction: c, rays: closure_rays as u32, group })
    } else {
        None
    };
    let mut stats = HierarchyStats {
        link_nodes: link_nodes(&tree, ctx.min_size),
        closure_rays: closure_rays as u64,
        min_size: ctx.min_size,
        direct_emitters: ctx.direct.as_ref().map_or(0, |d| d.len() as u64),
        direct_rays,
        ..Default::default()
    };
    let mut parts = Vec::with_capacity(results.len());
    let mut exclusions = Vec::new();
    for (l, mut ex, c) in results {
        parts.push(l);
        exclusions.append(&mut ex);
        stats.pairs_examined += c.pairs;
        stats.partial_refined += c.partial;
        stats.terminal_links += c.terminal;
        stats.coarse_links += c.coarse;
        stats.glimpsed += c.glimpsed;
    }
    let emitters = ctx.direct.clone();
    // Rays find emitted light poorly where it is concentrated: traced rows only where the
    // direct columns carry it, or where emission is spread (a furnace, a glowing wall).
    let traced = emitters.is_some() || !ctx.sharp;
    drop(ctx);
    // Its own stage in the report: seconds on a large scene (the links into one array, the
    // closure fit and the row guard, each a pass over every link).
    progress.begin("link assembly", 1);
    let mut h = Hierarchy::from_parts(tree, parts, exclusions, direct_rows, closure, stats);
    progress.end();
    if let Some(fraction) = h.closure().map(|c| &c.fraction).filter(|_| traced) {
        // Elements whose rows fall far short of their closure gather by rays instead.
        let sums = h.row_sums();
        let m = closure_rays as f64;
        // Also rows the fit could not bring to their closure: scaled by the largest factor
        // allowed and still short (in the conference furnace 16 293 elements read 1–9 %
        // dark between 0.877, the lower bound for 16 hits of 16, and their target of 1).
        let top = crate::transport::hierarchical::CLOSURE_SCALE.1 as f32;
        let poor: Vec<u32> = (0..n as u32)
            .filter(|&i| {
                let c = fraction[i as usize] as f64;
                c > 0.0
                    && (sums[i as usize] < crate::transport::hierarchical::wilson(c, m, RAY_ROW_Z).0
                        || h.link_scale()[i as usize] >= top)
            })
            .collect();
        if !poor.is_empty() {
            let locator = crate::mesh::Locator::new(mesh);
            let m = RAY_ROW_FACTOR * closure_rays;
            progress.begin("ray rows", poor.len() as u64);
            let rows: Vec<(u32, Vec<(u32, f32)>)> = poor
                .par_iter()
                .with_min_len(64)
                .map(|&i| {
                    if stopped.load(Ordering::Relaxed) || progress.should_stop() {
                        stopped.store(true, Ordering::Relaxed);
                        return (i, Vec::new());
                    }
                    progress.advance(1);
                    let row = ray_row(&h.tree, mesh, rays, receivers, &locator, emitters.as_deref(), ff.seed, m, eps, i);
                    total_rays.fetch_add(m as u64, Ordering::Relaxed);
                    (i, row)
                })
                .collect();
            progress.end();
            if stopped.load(Ordering::Relaxed) {
                return Err(Error::Cancelled);
            }
            progress.begin("row refit", 1);
            h.set_ray_rows(rows);
            progress.end();
        }
    }
    Ok((h, total_rays.load(Ordering::Relaxed)))
}

/// Rows whose sum (after the closure fit) is below the lower end of the Wilson interval
/// of the element's closure at this many standard deviations are traced by rays
/// ([`ray_row`]): a row far short of what its own rays show (0.88 for an element whose 16
/// closure rays all met a front face), not a row that a few rays cannot tell from its
/// closure (an element under a small light in an open scene). So are rows that the fit
/// scaled by the largest factor it allows ([`crate::transport::hierarchical::CLOSURE_SCALE`]),
/// which then still fall short of its target.
const RAY_ROW_Z: f64 = 1.5;

/// Rays of a traced row, in closure rays.
const RAY_ROW_FACTOR: usize = 2;

/// Casts `m` rays from element `i`'s open points (cycled), stratified over the
/// cosine-weighted hemisphere about its normal with a stream drawn from `seed`, and hands
/// each direction and first hit (the face it meets, as [`SceneRays::closest_facing`]) to
/// `visit`. False when the element has no open point (nothing cast).
#[allow(clippy::too_many_arguments)]
fn hemisphere_rays(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    seed: u64,
    m: usize,
    eps: f64,
    i: usize,
    mut visit: impl FnMut(DVec3, DVec3, Option<(crate::accel::Hit, u32)>),
) -> bool {
    use rand::RngExt;
    let e = &mesh.elements[i];
    let pts = receivers.points(i, 2);
    if pts.is_empty() {
        return false;
    }
    let mut rng = rng_for(seed, i as u64);
    let (t, b) = crate::sampling::basis(e.normal);
    let shift: f64 = rng.random();
    for k in 0..m {
        let p = pts[k % pts.len()] + e.normal * eps;
        let (u1, u2) = ((k as f64 + rng.random::<f64>()) / m as f64, (k as f64 * 0.618_033_988_75 + shift).fract());
        let d = crate::sampling::cosine_hemisphere(u1, u2);
        let dir = t * d.x + b * d.y + e.normal * d.z;
        visit(p, dir, rays.closest_facing(p.as_vec3(), dir.as_vec3(), f32::INFINITY, Some(e.patch)));
    }
    true
}

/// Element `i`'s row traced by `m` rays ([`hemisphere_rays`]): the share of rays whose
/// first hit is the front of element `j` is `F_ij` (the Monte Carlo form factor; emitting
/// elements that the direct columns hold are left out).
#[allow(clippy::too_many_arguments)]
fn ray_row(
    tree: &Tree,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    locator: &crate::mesh::Locator,
    emitters: Option<&[u32]>,
    seed: u64,
    m: usize,
    eps: f64,
    i: u32,
) -> Vec<(u32, f32)> {
    if !(tree.nodes[tree.leaf_of[i as usize] as usize].area > 0.0) {
        return Vec::new();
    }
    let mut hits: Vec<u32> = Vec::with_capacity(m);
    hemisphere_rays(mesh, rays, receivers, seed ^ 0x5241_5952, m, eps, i as usize, |p, dir, hit| {
        if let Some(j) = locator.front_hit(mesh, rays, p, dir, hit) {
            if j != i && !emitters.is_some_and(|em| em.binary_search(&j).is_ok()) {
                // An element the coverage test found covered (no open area: nothing links
                // to it, and it gathers nothing) holds only its emission; the ray met it
                // all the same (the inside of a thin closed slab, whose faces across the
                // gap count as in contact). Its light is taken to be the element's own.
                let covered = !(tree.nodes[tree.leaf_of[j as usize] as usize].area > 0.0);
                hits.push(if covered { i } else { j });
            }
        }
    });
    hits.sort_unstable();
    let mut row: Vec<(u32, f32)> = Vec::new();
    for j in hits {
        match row.last_mut() {
            Some(last) if last.0 == j => last.1 += 1.0,
            _ => row.push((j, 1.0)),
        }
    }
    for r in &mut row {
        r.1 /= m as f32;
    }
    row
}

/// The closure of element `i` from `m` rays ([`hemisphere_rays`]): the fraction whose
/// first hit is a front face (NaN for an element with no open area); its *exposure*, the
/// fraction that meets nothing within `reach` ([`exposure_reach`]: they leave the element's
/// neighbourhood, so far nodes can see it; 1 for an element with no open area); and the
/// rays cast.
#[allow(clippy::too_many_arguments)]
fn closure(
    tree: &Tree,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    seed: u64,
    m: usize,
    eps: f64,
    reach: f64,
    i: usize,
) -> (f32, f32, u64) {
    if !(tree.nodes[tree.leaf_of[i] as usize].area > 0.0) {
        return (f32::NAN, 1.0, 0);
    }
    let (mut hit, mut open) = (0, 0);
    let cast = hemisphere_rays(mesh, rays, receivers, seed ^ 0x434c_4f53, m, eps, i, |_, dir, h| match h {
        Some((h, q)) => {
            hit += (rays.normal_of(q).dot(dir.as_vec3()) < 0.0) as u32;
            open += (h.t as f64 > reach) as u32;
        }
        None => open += 1,
    });
    if !cast {
        return (f32::NAN, 1.0, 0);
    }
    (hit as f32 / m as f32, open as f32 / m as f32, m as u64)
}

/// `(size_R + size_S) / r` between the centroids; infinite when the boxes overlap (never
/// well separated).
fn separation_ratio(nr: &Node, ns: &Node) -> f64 {
    let dist = (ns.centroid - nr.centroid).length() as f64;
    let boxes_apart = nr.lo.cmpgt(ns.hi).any() || ns.lo.cmpgt(nr.hi).any();
    if boxes_apart && dist > 0.0 {
        (nr.size() + ns.size()) / dist
    } else {
        f64::INFINITY
    }
}

/// The emitting elements of a node: their bounding box and the cone of their normals.
/// A cluster that emits unequally may still be a source for a receiver that lies in front
/// of every one of its emitting elements: its directional reading then mixes only light
/// the receiver could see (a sky-lit courtyard floor read from the galleries above it),
/// while one whose emitting faces turn away from the receiver (the lit roof of a slab, read
/// from the room below) must be split ([`Ctx::emits_unseen`]).
#[derive(Clone, Copy, Debug)]
struct LitFaces {
    lo: Vec3,
    hi: Vec3,
    /// Area-weighted mean normal of the emitting elements.
    axis: Vec3,
    /// Cosine of the cone's half angle about `axis` (−2 when unknown or wider than 90°).
    cos: f32,
}

impl LitFaces {
    const NONE: LitFaces = LitFaces { lo: Vec3::ZERO, hi: Vec3::ZERO, axis: Vec3::ZERO, cos: -2.0 };

    /// For every node flagged in `emits` (others get [`LitFaces::NONE`]): one pass over its
    /// elements, O(n log n) over a balanced tree.
    fn of_nodes(tree: &Tree, emission: &[Rgb], emits: &[bool]) -> Vec<LitFaces> {
        (0..tree.nodes.len())
            .into_par_iter()
            .map(|k| {
                if !emits[k] {
                    return LitFaces::NONE;
                }
                let nd = &tree.nodes[k];
                let ids = &tree.order[nd.first as usize..(nd.first + nd.count) as usize];
                let leaves = || {
                    ids.iter()
                        .filter(|&&e| emission[e as usize].max_element() > 0.0)
                        .map(|&e| &tree.nodes[tree.leaf_of[e as usize] as usize])
                };
                let (mut lo, mut hi, mut sum) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY), Vec3::ZERO);
                for l in leaves() {
                    lo = lo.min(l.lo);
                    hi = hi.max(l.hi);
                    sum += l.n_sum;
                }
                let axis = sum.normalize_or_zero();
                if axis == Vec3::ZERO {
                    return LitFaces::NONE;
                }
                let cos = leaves().map(|l| l.n_sum.normalize_or_zero().dot(axis)).fold(1.0f32, f32::min);
                // Rounding of f32 normals: a cone a little wider than measured.
                let cos = if cos > 1e-3 { (cos - 1e-4).min(1.0) } else { -2.0 };
                LitFaces { lo, hi, axis, cos }
            })
            .collect()
    }
}

/// Range of the signed distance of a box's corners from a plane.
fn box_plane_range(nd: &Node, p: DVec3, n: DVec3) -> (f64, f64) {
    let (lo, hi) = (nd.lo.as_dvec3(), nd.hi.as_dvec3());
    let c = 0.5 * (lo + hi) - p;
    let h = 0.5 * (hi - lo);
    let mid = n.dot(c);
    let r = h.x * n.x.abs() + h.y * n.y.abs() + h.z * n.z.abs();
    (mid - r, mid + r)
}

impl Ctx<'_> {
    fn node(&self, k: u32) -> &Node {
        &self.tree.nodes[k as usize]
    }

    /// True for a near-field pair: bounding boxes nearer than the exposure's reach. Light
    /// between them reaches every face facing the other; beyond it a cluster sends and
    /// receives through its exposed faces only, those whose rays get past the reach
    /// ([`crate::transport::hierarchical::Tree::set_exposure`]).
    #[inline]
    fn near(&self, r: u32, s: u32) -> bool {
        let (a, b) = (self.node(r), self.node(s));
        let gap = (a.lo - b.hi).max(b.lo - a.hi).max(glam::Vec3::ZERO);
        (gap.length() as f64) < self.reach
    }

    /// The projected area of node `k` towards `d`: of all its faces for a near pair, of
    /// its exposed faces for a far one.
    #[inline]
    fn projected(&self, k: u32, d: DVec3, near: bool) -> f64 {
        self.tree.projected_area(k, d, !near)
    }

    fn refine_root(&self, root: u32, links: &mut Vec<Link>, exclusions: &mut Vec<Exclusion>, c: &mut Counts) {
        let mut rng = rng_for(self.ff.seed ^ 0x4849_4552, root as u64);
        let mut stack = vec![(root, 0u32)];
        let mut scratch = Scratch::default();
        while let Some((r, s)) = stack.pop() {
            c.pairs += 1;
            let (nr, ns) = (self.node(r), self.node(s));
            if ns.area <= 0.0 || nr.area <= 0.0 {
                continue;
            }
            if self.direct.is_some() && self.emits_any[s as usize] {
                // Emitted light goes through the direct columns; only S's parts that emit
                // nothing are sources here. S is opened to reach them — unless it is well
                // separated from R and hidden from it (another room of a building, lamps
                // and all): opening it would pair R with every fragment beside each lamp.
                if !ns.is_leaf() && !self.hidden(r, s, &mut rng, c) {
                    stack.push((r, ns.child[0]));
                    stack.push((r, ns.child[1]));
                }
                continue;
            }
            if self.tree.contains(s, r) {
                // S holds R: the same plane (nothing), or a cluster to open.
                if !ns.surface {
                    stack.push((r, ns.child[0]));
                    stack.push((r, ns.child[1]));
                }
                continue;
            }
            if self.tree.contains(r, s) {
                // R holds S: a cluster to open (a surface node cannot see itself).
                if !nr.surface {
                    stack.push((nr.child[0], s));
                    stack.push((nr.child[1], s));
                }
                continue;
            }
            if !nr.surface {
                self.refine_cluster_receiver(r, s, &mut stack, links, &mut rng, &mut scratch, c);
                continue;
            }
            let (pr, n_r) = (nr.centroid.as_dvec3(), nr.normal());
            let tol = self.eps + 1e-6 * nr.size().max(ns.size());
            let (dmin, dmax) = box_plane_range(ns, pr, n_r);
            if dmax <= tol {
                continue; // behind R or in its plane
            }
            if ns.surface {
                let (_, b) = box_plane_range(nr, ns.centroid.as_dvec3(), ns.normal());
                if b <= tol {
                    continue; // R behind S
                }
                // Back to back in one plane: the two sides of a two-sided polygon. The box
                // tests above miss them when the plane is tilted (a box's corners lie off
                // it), and a point of R then read its own back copy as a whole hemisphere
                // (`point_to_polygon` on a polygon around the point, in its tangent plane):
                // McGuire's Cornell box `--two-sided`, whose left wall is a warped quad
                // split in two, had rows of 1.3–1.6 that the guard halved, the wall 10 %
                // dark. Point-sampled rows skip such pairs likewise (`facing_patches`).
                if ns.normal().dot(n_r) < -1.0 + 1e-6 && n_r.dot(ns.centroid.as_dvec3() - pr).abs() <= tol {
                    continue;
                }
            }
            // A source straddling R's plane is opened (the part behind R sends nothing),
            // down to the minimum size: below it the point-by-point integral of a terminal
            // link drops what lies behind.
            let straddles = dmin < -tol && self.splittable(s);
            if (straddles || (!ns.surface && self.emits_unseen(r, s))) && !ns.is_leaf() {
                stack.push((r, ns.child[0]));
                stack.push((r, ns.child[1]));
                continue;
            }
            if nr.is_leaf() && ns.is_leaf() {
                let i = self.tree.order[nr.first as usize];
                let j = self.tree.order[ns.first as usize];
                let f = self.leaf_factor(i, j, false, &mut rng, &mut scratch, c);
                if f > 0.0 {
                    links.push(Link { r, s, f: f as f32, g: [0.0; 3], dir: Link::MEAN, near: false });
                }
                continue;
            }
            let ratio = separation_ratio(nr, ns);
            let (cr, cs) = (self.splittable(r), self.splittable(s));
            // Two nodes at the minimum size are linked as they are, separated or not.
            let terminal = !cr && !cs;
            if terminal && ratio.is_infinite() && self.open_overlap(r, s, &mut stack) {
                continue;
            }
            if let Some(minor) = self.integrate_here(terminal, r, s, ratio, &mut scratch, c) {
                // Near each other: integrated with the rays themselves.
                let near = self.near(r, s);
                let (f, _) = self.terminal_factor(r, s, near, minor, &mut rng, c, &mut scratch);
                if f > 0.0 {
                    let dir = if ns.surface { Link::MEAN } else { self.reading(r, s, near) };
                    links.push(Link { r, s, f: f as f32, g: [0.0; 3], dir, near });
                }
                continue;
            }
            if ratio < self.opts.separation {
                // Only candidate links are estimated (pairs that will be split are not).
                let near = self.near(r, s);
                let (f, g) = self.estimate(r, s, ratio, near, &mut scratch);
                let power = f * nr.area as f64 * self.b_hat[s as usize] as f64 * self.rho[r as usize] as f64;
                if f <= 0.0 {
                    continue;
                }
                let minor = power <= self.power_eps;
                let (v, mut partial) = self.visibility(r, s, minor, near, !terminal && !minor, &mut rng, c);
                if !terminal && !minor && !partial && v == 0.0 {
                    // Hidden to every ray, yet above the tolerance: light that reaches R
                    // through a slit (a lamp 1 cm under a ceiling lights a spot there that
                    // the room sees only past the lamp's edge) has a visible share too
                    // small for 8 rays, and was dropped with the link.
                    partial = self.glimpse(r, s, near, power, &mut rng, c);
                    c.glimpsed += partial as u64;
                }
                if terminal || !(partial && !minor) {
                    if v > 0.0 {
                        let dir = if ns.surface { Link::MEAN } else { self.reading(r, s, near) };
                        links.push(Link { r, s, f: (f * v) as f32, g: (g * v).as_vec3().to_array(), dir, near });
                    }
                    continue;
                }
                c.partial += 1;
            }
            // Split the larger node (one at the minimum size, or a leaf, is not split).
            let split_s = !cr || (cs && ns.size() >= nr.size());
            if split_s {
                stack.push((r, ns.child[0]));
                stack.push((r, ns.child[1]));
            } else {
                stack.push((nr.child[0], s));
                stack.push((nr.child[1], s));
            }
        }
        exclusions.append(&mut scratch.exclusions);
    }

    /// The topmost surface nodes below cluster `r` that see nothing of `s`, into
    /// `sc.behind`. For a surface `s`: among those not wholly in front of `s`'s plane, the
    /// ones wholly in it or behind it that do not face the way `s` does, and the ones whose
    /// own plane has all of `s` in it or behind it; at most [`BEHIND_VISITS`] nodes are
    /// visited (a large cluster keeps the rest lit). For a cluster `s` (terminal links
    /// only): the ones whose own plane has all of `s` in it or behind it, when `r` has at
    /// most [`BEHIND_CLUSTER_FACES`] topmost faces (every receiver made Sponza's links 30 %
    /// slower; BENCHMARKS.md, "Seventeenth round"). A link from `s` to `r` would light them
    /// by their normals alone ([`Exclusion`]).
    fn faces_behind(&self, r: u32, s: u32, tol: f64, sc: &mut Scratch) {
        sc.behind.clear();
        let ns = self.node(s);
        if !ns.surface {
            // A cluster: R's topmost faces, with S wholly in their plane or behind it;
            // only for a receiver of at most BEHIND_CLUSTER_FACES faces.
            let [a, b] = self.tree.top_range[r as usize];
            if (b - a) as usize <= BEHIND_CLUSTER_FACES {
                sc.behind.extend(self.tree.top_id[a as usize..b as usize].iter().filter_map(|&q| {
                    let nq = self.node(q);
                    (nq.area > 0.0 && box_plane_range(ns, nq.centroid.as_dvec3(), nq.normal()).1 <= tol).then_some((q, 0.0))
                }));
            }
            return;
        }
        let (p, n) = (ns.centroid.as_dvec3(), ns.normal());
        if box_plane_range(self.node(r), p, n).0 > tol {
            return; // wholly in front
        }
        let mut walk = std::mem::take(&mut sc.behind_walk);
        walk.clear();
        walk.push(r);
        let mut visits = 0;
        while let Some(q) = walk.pop() {
            visits += 1;
            if visits > BEHIND_VISITS {
                break;
            }
            let nq = self.node(q);
            if !(nq.area > 0.0) {
                continue;
            }
            let (a, b) = box_plane_range(nq, p, n);
            if a > tol {
                continue; // wholly in front of S
            }
            if nq.surface {
                // Wholly in S's plane or behind it, or S wholly in its plane or behind it.
                let behind_s = b <= tol && nq.normal().dot(n) < 0.999;
                if behind_s || box_plane_range(ns, nq.centroid.as_dvec3(), nq.normal()).1 <= tol {
                    sc.behind.push((q, 0.0));
                }
                continue;
            }
            walk.extend(nq.child.into_iter().filter(|&c| c != NONE));
        }
        sc.behind_walk = walk;
    }

    /// For a link from `s` to cluster `r` arriving from `d`: keeps in `sc.behind` the faces
    /// of `r` that see nothing of `s` ([`Ctx::faces_behind`]) and would take at least
    /// [`BEHIND_SHARE`] of what the link hands out, each with its front area
    /// (`Tree::front_area`, its share of the link's spread), and returns their sum. Smaller ones stay
    /// lit: on Sponza, two-sided throughout, recording every one took more memory than the
    /// links.
    /// `front`: `r`'s front area towards `d` where the caller has it.
    #[allow(clippy::too_many_arguments)]
    fn behind_shares(&self, r: u32, s: u32, tol: f64, d: DVec3, near: bool, front: Option<f64>, sc: &mut Scratch) -> f64 {
        self.faces_behind(r, s, tol, sc);
        if sc.behind.is_empty() {
            return 0.0;
        }
        let floor = BEHIND_SHARE * front.unwrap_or_else(|| self.tree.front_area(r, d, !near));
        for (q, share) in sc.behind.iter_mut() {
            *share = self.tree.front_area(*q, d, !near);
        }
        sc.behind.retain(|&(_, share)| share > 0.0 && share >= floor);
        sc.behind.iter().map(|&(_, share)| share).sum()
    }

    /// Records the faces in `sc.behind` ([`Ctx::behind_shares`]) as exclusions of a link of
    /// factor `w` from `s`: what the walk would hand each of them, `w` × its share over
    /// its area.
    fn exclude_behind(&self, s: u32, w: f64, near: bool, dir: [f32; 4], sc: &mut Scratch) {
        for &(q, share) in &sc.behind {
            let a = self.node(q).area as f64;
            if a > 0.0 {
                sc.exclusions.push(Exclusion { c: q, s, coef: (w * share / a) as f32, dir, near });
            }
        }
    }

    /// True when neither of `r`, `s` holds the other, they are well separated and every
    /// visibility ray between them is blocked.
    fn hidden(&self, r: u32, s: u32, rng: &mut Rng, c: &mut Counts) -> bool {
        if self.tree.contains(s, r) || self.tree.contains(r, s) {
            return false;
        }
        if separation_ratio(self.node(r), self.node(s)) >= self.opts.separation {
            return false;
        }
        let near = self.near(r, s);
        let (v, partial) = self.visibility(r, s, false, near, true, rng, c);
        v == 0.0 && !partial
    }

    /// The direct columns: every element's factors to the emitting elements `em` it may
    /// see ([`Ctx::direct_row`]). Groups of receivers (nodes of the element tree with at
    /// most [`RECEIVER_GROUP`] elements) first cull what none of their elements can see —
    /// the lamps of other rooms once per group instead of once per element — and each
    /// element's walk starts from what its group left.
    fn direct_columns(
        &self,
        em: &[u32],
        progress: &dyn Progress,
        stopped: &AtomicBool,
        total_rays: &AtomicU64,
    ) -> Result<crate::transport::SparseRows> {
        let (mesh, tree, n) = (self.mesh, self.tree, self.mesh.len());
        let nodes = &tree.nodes;
        let em = EmitterTree::build(mesh, em);
        let mut groups = Vec::new();
        let mut stack = if nodes.is_empty() { Vec::new() } else { vec![0u32] };
        while let Some(k) = stack.pop() {
            let nd = &nodes[k as usize];
            if nd.count as usize <= RECEIVER_GROUP || nd.is_leaf() {
                groups.push(k);
            } else {
                stack.extend(nd.child);
            }
        }
        let starts: Vec<Vec<u32>> = groups
            .par_iter()
            .map(|&k| {
                let nd = &nodes[k as usize];
                let elements = &tree.order[nd.first as usize..(nd.first + nd.count) as usize];
                let mut rng = rng_for(self.ff.seed ^ 0x4752_4f55, k as u64);
                let mut out = Vec::new();
                let cast = em.for_group(mesh, self.rays, self.receivers, elements, self.eps, &mut rng, &mut out);
                total_rays.fetch_add(cast, Ordering::Relaxed);
                out
            })
            .collect();
        let mut group_of = vec![0u32; n];
        for (g, &k) in groups.iter().enumerate() {
            let nd = &nodes[k as usize];
            for &e in &tree.order[nd.first as usize..(nd.first + nd.count) as usize] {
                group_of[e as usize] = g as u32;
            }
        }
        let rows = per_element(n, "direct light", progress, stopped, Vec::new(), |i| {
            let mut c = Counts::default();
            let row = self.direct_row(i, &em, &starts[group_of[i as usize] as usize], &mut c);
            total_rays.fetch_add(c.rays, Ordering::Relaxed);
            row
        })?;
        Ok(crate::transport::SparseRows::from_rows(rows))
    }

    /// Element `i`'s factors to the emitting elements it may see (`em` walked from the
    /// nodes `start`, ascending), point-sampled with visibility ([`Ctx::leaf_factor`]);
    /// pairs behind each other's plane are skipped.
    fn direct_row(&self, i: u32, em: &EmitterTree, start: &[u32], c: &mut Counts) -> Vec<(u32, f32)> {
        let mesh = self.mesh;
        let mut rng = rng_for(self.ff.seed ^ 0x4449_5245, i as u64);
        // The groups' culling draws from its own stream: where nothing is culled the
        // factors are those of testing every emitter.
        let mut cull_rng = rng_for(self.ff.seed ^ 0x4355_4c4c, i as u64);
        let (mut stack, mut candidates) = (Vec::new(), Vec::new());
        c.rays += em.visible_from(mesh, self.rays, self.receivers, i, start, self.eps, &mut cull_rng, &mut stack, &mut candidates);
        let mut sc = Scratch::default();
        let ei = &mesh.elements[i as usize];
        let (ci, ni) = ei.corners(&mesh.positions);
        let mut row = Vec::new();
        for &j in &candidates {
            if j == i {
                continue;
            }
            let ej = &mesh.elements[j as usize];
            let (cj, nj) = ej.corners(&mesh.positions);
            let ahead = |c: &[DVec3], p: DVec3, n: DVec3| c.iter().any(|&q| n.dot(q - p) > self.eps);
            if !ahead(&cj[..nj], ei.centroid, ei.normal) || !ahead(&ci[..ni], ej.centroid, ej.normal) {
                continue;
            }
            let f = self.leaf_factor(i, j, true, &mut rng, &mut sc, c);
            if f > 0.0 {
                row.push((j, f as f32));
            }
        }
        row
    }

    /// Two nodes at the minimum size whose boxes overlap (parts of each lie on both sides of
    /// the other: a window frame in its wall, a ledge over a gallery), the source emitting
    /// unequally, are opened further instead of linked: a terminal link integrates the
    /// geometry point by point, but reads the source as one directional average, in which
    /// the faces that the receiver cannot see (the sky-lit outside of the wall behind a
    /// window) count as much as those it sees. Under a sky that lit Sponza's windows 3.3×
    /// too bright (BENCHMARKS.md, "Sky"). Opening every overlapping pair also stops the
    /// conference room creating light (escaped −0.66 % → +0.21 %), but triples its links'
    /// time; restricted to unequal emitters it costs the conference nothing.
    /// Splits the larger of the two that is not a leaf; false when both are leaves.
    fn open_overlap(&self, r: u32, s: u32, stack: &mut Vec<(u32, u32)>) -> bool {
        if !self.emits[s as usize] {
            return false;
        }
        let (nr, ns) = (self.node(r), self.node(s));
        let split_s = !ns.is_leaf() && (nr.is_leaf() || ns.size() >= nr.size());
        if split_s {
            stack.push((r, ns.child[0]));
            stack.push((r, ns.child[1]));
            true
        } else if !nr.is_leaf() {
            stack.push((nr.child[0], s));
            stack.push((nr.child[1], s));
            true
        } else {
            false
        }
    }

    /// True when source `s` emits unequally and some of its emitting elements may face away
    /// from receiver `r` (see [`LitFaces`]). Conservative: every direction `v = x − p` from
    /// a point `p` of the emitting box to a point `x` of `r`'s box must lie within 90° of
    /// every normal of the cone, `v·a cos θ > |v| sin θ`, bounded over the box of all `v`.
    fn emits_unseen(&self, r: u32, s: u32) -> bool {
        if !self.emits[s as usize] {
            return false;
        }
        let lit = &self.lit[s as usize];
        if lit.cos <= 0.0 {
            return true;
        }
        let nr = self.node(r);
        let (vlo, vhi) = ((nr.lo - lit.hi).as_dvec3(), (nr.hi - lit.lo).as_dvec3());
        let a = lit.axis.as_dvec3();
        let min_dot: f64 = (0..3).map(|i| (vlo[i] * a[i]).min(vhi[i] * a[i])).sum();
        let max_len = (0..3).map(|i| (vlo[i] * vlo[i]).max(vhi[i] * vhi[i])).sum::<f64>().sqrt();
        let cos = lit.cos as f64;
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        !(min_dot * cos > max_len * sin + self.eps)
    }

    /// Whether a pair that is not well separated (`ratio ≥ θ`) is linked as it stands with
    /// its factor integrated point by point: two nodes at the minimum size (`terminal`), or
    /// a pair [`Ctx::coarse`] lets stop above it. Counts which. `Some(minor)` when it is,
    /// with `minor` true where the link's rough power is at most the link tolerance (always
    /// so for a coarse pair), so that the quick estimate will do ([`QUICK_TERMINAL_SHARE`]).
    fn integrate_here(&self, terminal: bool, r: u32, s: u32, ratio: f64, sc: &mut Scratch, c: &mut Counts) -> Option<bool> {
        if ratio < self.opts.separation {
            return None;
        }
        if terminal {
            c.terminal += 1;
            return Some(self.minor(r, s, ratio, sc));
        }
        let coarse = self.coarse(r, s, ratio, sc);
        c.coarse += coarse as u64;
        coarse.then_some(self.power_eps > 0.0)
    }

    /// True when a link from `s` to `r` carries at most the link tolerance by its rough
    /// power ([`Ctx::rough_power`]): decided before any ray, so that choosing the quick
    /// estimate on it does not select the draws it is made for.
    fn minor(&self, r: u32, s: u32, ratio: f64, sc: &mut Scratch) -> bool {
        self.power_eps > 0.0 && self.rough_power(r, s, ratio, self.near(r, s), sc).is_some_and(|p| p <= self.power_eps)
    }

    /// BF refinement near the minimum size: true for a pair that is not well separated
    /// but not close either (ratio below [`COARSE_SEPARATION`] × the separation), both
    /// nodes at most [`Options::coarse_size`] × the minimum size, whose estimated link
    /// carries at most `tolerance × total power` (`power_eps`): it is linked where it
    /// stands, its factor integrated point by point like a terminal link's, instead of
    /// being split down to the minimum size. Never towards concentrated emitters (their
    /// light needs the refinement; a cluster takes none of it). A cluster receiver's coarse
    /// link, like a terminal one, is spread over its front faces whether partly visible or
    /// not (the power limit bounds what that moves).
    fn coarse(&self, r: u32, s: u32, ratio: f64, sc: &mut Scratch) -> bool {
        let k = self.opts.coarse_size;
        if !(k > 0.0 && self.min_size > 0.0 && ratio < COARSE_SEPARATION * self.opts.separation) {
            return false;
        }
        if self.sharp && self.emits_any[s as usize] {
            return false;
        }
        let (nr, ns) = (self.node(r), self.node(s));
        if nr.size() > k * self.min_size || ns.size() > k * self.min_size {
            return false;
        }
        let near = self.near(r, s);
        self.rough_power(r, s, ratio, near, sc).is_some_and(|p| p <= self.power_eps)
    }

    /// The power `ρ_R · B̂_S · F̃ · A_R` a link from `s` to `r` would carry, with `F̃` the
    /// unoccluded factor estimated without rays: [`Ctx::estimate`] for a surface receiver,
    /// a disk of `s`'s projected area seen from `r`'s centroid for a cluster. None for a
    /// cluster receiver whose centroid is `s`'s. Deterministic, so that choices made on it (coarse links, the
    /// quick terminal estimate) do not select the sampled factors they are made for.
    fn rough_power(&self, r: u32, s: u32, ratio: f64, near: bool, sc: &mut Scratch) -> Option<f64> {
        let (nr, ns) = (self.node(r), self.node(s));
        let f = if nr.surface {
            self.estimate(r, s, ratio, near, sc).0
        } else {
            let d = ns.centroid.as_dvec3() - nr.centroid.as_dvec3();
            let r2 = d.length_squared();
            if !(r2 > 0.0) {
                return None;
            }
            disk_factor(self.projected(s, -d / r2.sqrt(), near), r2)
        };
        Some(f * nr.area as f64 * self.b_hat[s as usize] as f64 * self.rho[r as usize] as f64)
    }

    /// True when node `k` may be split to refine a link: not a leaf, and larger than
    /// [`Options::min_size`] both across and in area (`min_size²`).
    #[inline]
    fn splittable(&self, k: u32) -> bool {
        let nd = self.node(k);
        // By extent, and by area: a sliver (a long thin triangle, cut by the mesher into
        // long thin elements) spans more than the minimum size with a tiny share of the
        // scene's area.
        !nd.is_leaf() && nd.size() > self.min_size && nd.area as f64 > self.min_size * self.min_size
    }

    /// One pair whose receiver `r` is a cluster: linked (irradiance per unit cosine from the
    /// direction of `s`, see [`crate::transport::hierarchical::DIR_BIN_SIDE`]) when well
    /// separated, `s` holds no concentrated emitter (`Ctx::sharp`) and visibility allows;
    /// else split.
    #[allow(clippy::too_many_arguments)]
    fn refine_cluster_receiver(
        &self,
        r: u32,
        s: u32,
        stack: &mut Vec<(u32, u32)>,
        links: &mut Vec<Link>,
        rng: &mut Rng,
        sc: &mut Scratch,
        c: &mut Counts,
    ) {
        let (nr, ns) = (self.node(r), self.node(s));
        let tol = self.eps + 1e-6 * nr.size().max(ns.size());
        if ns.surface {
            let (_, b) = box_plane_range(nr, ns.centroid.as_dvec3(), ns.normal());
            if b <= tol {
                return; // R behind S
            }
        }
        // A cluster that emits unequally is never a source (as for surface receivers): its
        // first-order directional reading mixes faces the receiver cannot see. Under a sky a
        // slab's lit roof and dark ceiling, read by a floor cluster inside, leaked light into
        // a closed room (max B 5.6e-2 against 1.58 outside; `tests/sky.rs`).
        if !ns.surface && self.emits_unseen(r, s) && !ns.is_leaf() {
            stack.push((r, ns.child[0]));
            stack.push((r, ns.child[1]));
            return;
        }
        let ratio = separation_ratio(nr, ns);
        // A cluster takes no light from concentrated emitters (it must be split down to
        // surfaces for that, whatever its size).
        let cr = self.splittable(r) || (self.sharp && self.emits_any[s as usize]);
        let cs = self.splittable(s);
        let terminal = !cr && !cs;
        if terminal && ratio.is_infinite() && self.open_overlap(r, s, stack) {
            return;
        }
        if let Some(minor) = self.integrate_here(terminal, r, s, ratio, sc, c) {
            // Near each other: the power R receives integrated with the rays, spread to
            // R's elements by their normals about the mean direction of arrival.
            let near = self.near(r, s);
            let (f, d) = self.terminal_factor(r, s, near, minor, rng, c, sc);
            if f > 0.0 && d != DVec3::ZERO {
                // R's faces behind a surface source take none of it: the rest share it.
                let front = self.tree.front_area(r, d, !near);
                let spread = front - self.behind_shares(r, s, tol, d, near, Some(front), sc);
                if spread > 1e-6 * nr.area as f64 {
                    let read = if ns.surface { Link::MEAN } else { self.reading_towards(s, -d, near) };
                    let w = (f * nr.area as f64 / spread).min(1.0);
                    links.push(Link { r, s, f: w as f32, g: d.as_vec3().to_array(), dir: read, near });
                    self.exclude_behind(s, w, near, read, sc);
                }
            }
            return;
        }
        if ratio < self.opts.separation && !(self.sharp && self.emits_any[s as usize]) {
            let near = self.near(r, s);
            let x = nr.centroid.as_dvec3();
            self.tree.frontier(s, SOURCE_FRONTIER, &mut sc.frontier);
            let mut k = 0.0;
            let mut dir = DVec3::ZERO;
            for &q in &sc.frontier {
                let nq = self.node(q);
                let d = nq.centroid.as_dvec3() - x;
                let r2 = d.length_squared();
                if nq.area <= 0.0 || r2 <= 0.0 {
                    continue;
                }
                let du = d / r2.sqrt();
                let kq = disk_factor(self.projected(q, -du, near), r2);
                k += kq;
                dir += du * kq;
            }
            // The vector irradiance `Σ k_q d_q`: a face of R with normal n takes
            // `n · Σ k_q d_q` (exact while the source lies above its horizon), which the
            // scalar `Σ k_q` along the mean direction would overstate by the source's spread.
            let d = dir.normalize_or_zero();
            if !(k > 0.0) || d == DVec3::ZERO {
                return;
            }
            let kv = dir.length();
            let power = k * self.projected(r, d, near) * self.b_hat[s as usize] as f64 * self.rho[r as usize] as f64;
            // Partly visible: always split, whatever the power (unlike a surface receiver).
            // The visible fraction is an average over the cluster's front faces, and one
            // part of a cluster often hides another (a ceiling behind a lamp housing, a
            // seat under a desk): handed to every face alike it lit the hidden ones as the
            // exposed ones, and the two-sided classroom came out 6.6 % brighter than the
            // ray-traced stochastic solve, light created (1.6 % once split).
            // No second look here (`Ctx::glimpse`): a cluster's hidden pair split into its
            // faces handed light to faces of the cluster that see nothing of the source;
            // measured, it made a closed room create 0.38 % (BENCHMARKS.md, round 24).
            let (v, partial) = self.visibility(r, s, power <= self.power_eps, near, !terminal, rng, c);
            if terminal || !partial {
                if v > 0.0 {
                    let read = if ns.surface { Link::MEAN } else { self.reading_towards(s, -d, near) };
                    let w = (kv * v).min(1.0);
                    links.push(Link { r, s, f: w as f32, g: d.as_vec3().to_array(), dir: read, near });
                    if ns.surface {
                        self.behind_shares(r, s, tol, d, near, None, sc);
                        self.exclude_behind(s, w, near, read, sc);
                    }
                }
                return;
            }
            c.partial += 1;
        }
        if cs && (!cr || ns.size() > nr.size()) {
            stack.push((r, ns.child[0]));
            stack.push((r, ns.child[1]));
        } else {
            stack.push((nr.child[0], s));
            stack.push((nr.child[1], s));
        }
    }

    /// The factor from node `r` to node `s`, averaged over `r`'s area, with visibility, for
    /// two nodes near each other (not well separated, neither split further): `N = 2 ×`
    /// [`Options::visibility_rays`] stratified point pairs (area-uniform, each point on its
    /// own element with that element's normal, so a cluster receiver's points face every
    /// way). The unoccluded factor at each point of `r` is [`Ctx::unoccluded_at`] (exact
    /// contour integrals near the point, so a shared edge's singular kernel is integrated,
    /// not sampled); the visible fraction comes from rays between the paired points,
    /// weighted by their kernel with each point of `s` standing for a disk of `A_S / N`
    /// (Wallace, Elmquist & Haines 1989), so that pairs that touch stay bounded. Also
    /// returns the mean direction of arrival (weighted by contribution). A `minor` link
    /// (rough power at most the link tolerance, [`Ctx::minor`]) is integrated from
    /// `N /` [`QUICK_TERMINAL_SHARE`] pairs.
    #[allow(clippy::too_many_arguments)]
    fn terminal_factor(&self, r: u32, s: u32, near: bool, minor: bool, rng: &mut Rng, c: &mut Counts, sc: &mut Scratch) -> (f64, DVec3) {
        let m = 2 * self.opts.visibility_rays;
        let quick = (m / QUICK_TERMINAL_SHARE).max(2);
        self.terminal_factor_with(r, s, near, if minor { quick.min(m) } else { m }, rng, c, sc)
    }

    /// [`Ctx::terminal_factor`] from `m` pairs of points.
    #[allow(clippy::too_many_arguments)]
    fn terminal_factor_with(
        &self,
        r: u32,
        s: u32,
        near: bool,
        m: usize,
        rng: &mut Rng,
        c: &mut Counts,
        sc: &mut Scratch,
    ) -> (f64, DVec3) {
        use rand::RngExt;
        let a_s = self.node(s).area as f64;
        let disk = a_s / m as f64;
        sc.pairs.clear();
        for t in 0..m {
            let ur = (t as f64 + rng.random::<f64>()) / m as f64;
            let us = ((t * 7 + 3) % m) as f64 / m as f64 + rng.random::<f64>() / m as f64;
            let (a, b) = (&self.samples[self.tree.slot_at(r, ur)], &self.samples[self.tree.slot_at(s, us)]);
            let x = a.point(rng.random(), rng.random());
            let y = b.point(rng.random(), rng.random());
            sc.pairs.push(((x, a.normal, a.patch), (y, b.normal, b.patch)));
        }
        let kernel = |x: DVec3, nx: DVec3, y: DVec3, ny: DVec3| {
            let d = y - x;
            let r2 = d.length_squared();
            if !(r2 > 0.0) {
                return (0.0, DVec3::ZERO);
            }
            let du = d / r2.sqrt();
            let (cx, cy) = (nx.dot(du), -ny.dot(du));
            if cx <= 0.0 || cy <= 0.0 {
                return (0.0, du);
            }
            (cx * cy / (std::f64::consts::PI * r2 + disk), du)
        };
        // Visible fraction of the paired points, weighted by their kernel.
        let (mut seen, mut weight) = (0.0, 0.0);
        for &(x, y) in &sc.pairs {
            let (k, _) = kernel(x.0, x.1, y.0, y.1);
            if k > 0.0 {
                c.rays += 1;
                weight += k;
                if self.rays.visible(x.0, x.2, y.0, y.2) {
                    seen += k;
                }
            }
        }
        let v = if weight > 0.0 { seen / weight } else { 0.0 };
        if v <= 0.0 {
            // Hidden (half of Sponza's terminal pairs): the factor is 0 whatever the
            // unoccluded one, which costs more than the rays.
            return (0.0, DVec3::ZERO);
        }
        // Unoccluded: at every point of `r`, against `s` opened near the point.
        let (mut unoccluded, mut dir, mut count) = (0.0, DVec3::ZERO, 0usize);
        for t in 0..sc.pairs.len() {
            let (x, nx, _) = sc.pairs[t].0;
            let (f, d) = self.unoccluded_at(x, nx, s, near, &mut sc.frontier);
            unoccluded += f;
            dir += d;
            count += 1;
        }
        ((unoccluded / count.max(1) as f64 * v).min(1.0), dir.normalize_or_zero())
    }

    /// The unoccluded factor from the point `x` (normal `n`) to node `s`, and its
    /// contribution-weighted direction: `s` is opened, Barnes–Hut fashion, where a node is
    /// within twice its size of `x` (up to [`NEAR_BUDGET`] nodes); elements take the exact
    /// contour integral, farther nodes a disk of their projected area.
    fn unoccluded_at(&self, x: DVec3, n: DVec3, s: u32, near: bool, stack: &mut Vec<u32>) -> (f64, DVec3) {
        let mesh = self.mesh;
        stack.clear();
        stack.push(s);
        let (mut f, mut dir, mut opened) = (0.0, DVec3::ZERO, 0usize);
        while let Some(q) = stack.pop() {
            let nq = self.node(q);
            if !(nq.area > 0.0) {
                continue;
            }
            let d = nq.centroid.as_dvec3() - x;
            let r2 = d.length_squared();
            let du = d.normalize_or_zero();
            let v = if nq.is_leaf() {
                let e = &mesh.elements[self.tree.order[nq.first as usize] as usize];
                let (c, nv) = e.corners(&mesh.positions);
                point_to_polygon(x, n, &c[..nv], e.normal)
            } else if r2 < 4.0 * nq.size() * nq.size() && opened < NEAR_BUDGET {
                opened += 1;
                stack.extend(nq.child);
                continue;
            } else {
                let cx = n.dot(du);
                if cx <= 0.0 || !(r2 > 0.0) {
                    continue;
                }
                cx * disk_factor(self.projected(q, -du, near), r2)
            };
            f += v;
            dir += du * v;
        }
        (f, dir)
    }

    /// Estimated unoccluded factor from node `r` (a surface node) to node `s`, averaged
    /// over `r`, and its gradient across `r` (zero for a leaf): a least-squares plane
    /// through the estimates at the receiver points.
    fn estimate(&self, r: u32, s: u32, ratio: f64, near: bool, sc: &mut Scratch) -> (f64, DVec3) {
        let nr = self.node(r);
        let n_r = nr.normal();
        sc.points.clear();
        if nr.is_leaf() {
            let e = self.tree.order[nr.first as usize] as usize;
            let k = if ratio < 0.25 { 1 } else { 2 };
            let pts = self.receivers.points(e, k);
            let w = 1.0 / pts.len().max(1) as f64;
            sc.points.extend(pts.iter().map(|&p| (p, w)));
        } else {
            self.tree.frontier(r, RECEIVER_FRONTIER, &mut sc.frontier);
            let total: f64 = sc.frontier.iter().map(|&q| self.node(q).area as f64).sum();
            for &q in &sc.frontier {
                let nq = self.node(q);
                if nq.area > 0.0 {
                    sc.points.push((nq.centroid.as_dvec3(), nq.area as f64 / total));
                }
            }
        }
        self.tree.frontier(s, SOURCE_FRONTIER, &mut sc.frontier);
        sc.values.clear();
        let mut f = 0.0;
        for &(x, w) in &sc.points {
            let mut fx = 0.0;
            for &q in &sc.frontier {
                let nq = self.node(q);
                if nq.area <= 0.0 {
                    continue;
                }
                let d = nq.centroid.as_dvec3() - x;
                let r2 = d.length_squared();
                let close = r2 <= 9.0 * nq.size() * nq.size();
                if nq.is_leaf() && close {
                    let e = &self.mesh.elements[self.tree.order[nq.first as usize] as usize];
                    let (c, nv) = e.corners(&self.mesh.positions);
                    fx += point_to_polygon(x, n_r, &c[..nv], e.normal);
                } else {
                    if r2 <= 0.0 {
                        continue;
                    }
                    let rl = r2.sqrt();
                    let cx = n_r.dot(d) / rl;
                    if cx <= 0.0 {
                        continue;
                    }
                    fx += cx * disk_factor(self.projected(q, -d / rl, near), r2);
                }
            }
            f += w * fx;
            sc.values.push(fx);
        }
        let mut grad = if nr.is_leaf() { DVec3::ZERO } else { plane_gradient(&sc.points, &sc.values, n_r, f) };
        // The linear term may not exceed the mean anywhere in the node (no negative or
        // runaway extrapolation from a poorly conditioned fit).
        let limit = 2.0 * f.max(0.0) / nr.size().max(f64::MIN_POSITIVE);
        let gl = grad.length();
        if gl > limit {
            grad *= limit / gl;
        }
        (f.min(1.0), grad)
    }

    /// Visible fraction between nodes `r` and `s` from area-uniform point pairs, and
    /// whether it is partial (some rays blocked, some not, or no usable pair).
    /// `minor` links (power below the tolerance, never refined) take half the rays. With
    /// `decide`, for a link that is split when partial, the rays stop at the first that
    /// disagrees with the others: the link is partial and its fraction is not read.
    #[allow(clippy::too_many_arguments)]
    fn visibility(&self, r: u32, s: u32, minor: bool, near: bool, decide: bool, rng: &mut Rng, c: &mut Counts) -> (f64, bool) {
        let m = if minor { self.opts.visibility_rays.div_ceil(2) } else { self.opts.visibility_rays };
        self.visibility_with(r, s, m, near, decide, rng, c)
    }

    /// True when a link of unoccluded power `power` that [`Ctx::visibility`] found hidden
    /// shows light after all, from more rays ([`GLIMPSE_PER_TOLERANCE`] per tolerance of
    /// power, at most [`GLIMPSE`] × the visibility rays; they stop at the first that gets
    /// through). The visibility rays are few (8): a link whose visible share `p` is small
    /// survives them with probability about `8p`, and only a surviving (partial) link is
    /// refined, so light through a slit was lost in proportion — the ceiling spot above a
    /// lamp 1 cm under it, seen by the room past the lamp's edge
    /// (`scenes/lamp-under-ceiling.toml`: the box 23 % dark).
    fn glimpse(&self, r: u32, s: u32, near: bool, power: f64, rng: &mut Rng, c: &mut Counts) -> bool {
        let most = GLIMPSE * self.opts.visibility_rays;
        let m = ((GLIMPSE_PER_TOLERANCE * power / self.power_eps).ceil() as usize).clamp(self.opts.visibility_rays, most);
        let (v, partial) = self.visibility_with(r, s, m, near, true, rng, c);
        partial || v > 0.0
    }

    /// [`Ctx::visibility`] from `m` rays.
    #[allow(clippy::too_many_arguments)]
    fn visibility_with(&self, r: u32, s: u32, m: usize, near: bool, decide: bool, rng: &mut Rng, c: &mut Counts) -> (f64, bool) {
        use rand::RngExt;
        let (mut valid, mut seen) = (0u32, 0u32);
        // Clusters of a far pair by their exposed area: their projected areas leave out
        // faces that no far node sees, so the rays test what lies between the nodes.
        let pick = |k: u32, u: f64| &self.samples[if near { self.tree.slot_at(k, u) } else { self.tree.slot_at_exposed(k, u) }];
        // A surface source's points by its estimated light `A·B̂` (area-uniform without
        // one): the visible share of its light, not of its area. The ceiling 0.01 above a
        // lamp's back side holds most of a ceiling node's light in a spot the lamp hides
        // from the room; area-uniform rays rarely met that spot, the link was kept whole at
        // the ceiling's mean visibility, and it carried the spot's light past the lamp.
        // A cluster source's likewise, over its exposed faces for a far pair: its reading
        // weighs its faces by projected area, not by what the receiver sees of them, so a
        // bright spot hidden from the receiver (the ceiling above a lamp) was read in full
        // while area-drawn rays found the cluster visible. Closed rooms with such a spot
        // created light (RenderPark's cube `--two-sided`: −0.80 % escaped, now −0.16 %).
        let ns = self.node(s);
        let prefix = if ns.surface || near { &self.light_prefix } else { &self.light_prefix_x };
        let light = prefix.as_deref().filter(|p| {
            // Nothing lit (or nothing exposed) there: area-drawn, as without an estimate.
            let (a, b) = (ns.first as usize, (ns.first + ns.count) as usize);
            ns.surface || p[b] > p[a]
        });
        let pick_s = |k: u32, u: f64| match light {
            Some(p) => &self.samples[self.tree.slot_by(p, k, u)],
            None => pick(k, u),
        };
        for t in 0..m {
            let ur = (t as f64 + rng.random::<f64>()) / m as f64;
            let us = ((t * 7 + 3) % m) as f64 / m as f64 + rng.random::<f64>() / m as f64;
            let (a, b) = (pick(r, ur), pick_s(s, us));
            let x = a.point(rng.random(), rng.random());
            let y = b.point(rng.random(), rng.random());
            if a.normal.dot(y - x) <= 0.0 || b.normal.dot(x - y) <= 0.0 {
                continue;
            }
            valid += 1;
            c.rays += 1;
            if self.rays.visible(x, a.patch, y, b.patch) {
                seen += 1;
            }
            if decide && seen != 0 && seen != valid {
                return (seen as f64 / valid as f64, true);
            }
        }
        if valid == 0 {
            return (1.0, true);
        }
        (seen as f64 / valid as f64, seen != 0 && seen != valid)
    }

    /// How a link from cluster `s` to node `r` reads it: as seen from `r`'s centroid.
    fn reading(&self, r: u32, s: u32, near: bool) -> [f32; 4] {
        let (nr, ns) = (self.node(r), self.node(s));
        self.reading_towards(s, (nr.centroid - ns.centroid).as_dvec3().normalize_or_zero(), near)
    }

    /// How a link reads cluster `s` seen from the unit direction `d` (from `s` towards the
    /// receiver).
    fn reading_towards(&self, s: u32, d: DVec3, near: bool) -> [f32; 4] {
        let p = self.projected(s, d, near);
        Link::directional(self.node(s), p, d, near)
    }

    /// Point-sampled factor between elements `i` (receiver) and `j`.
    fn leaf_factor(&self, i: u32, j: u32, exact_near: bool, rng: &mut Rng, sc: &mut Scratch, c: &mut Counts) -> f64 {
        let mesh = self.mesh;
        let (ei, ej) = (&mesh.elements[i as usize], &mesh.elements[j as usize]);
        let (cj, nv) = ej.corners(&mesh.positions);
        let cj = &cj[..nv];
        let d = (ej.centroid - ei.centroid).length();
        let size = ei.area.sqrt();
        let k = if d > 4.0 * size {
            1
        } else if d > 2.0 * size {
            2
        } else {
            self.ff.max_receiver_samples
        };
        if self.receivers.points(i as usize, k).is_empty() {
            return 0.0;
        }
        // Area-uniform points of the open part, stratified on the k × k grid of the
        // element's parameter domain, not the grid's fixed midpoints: next to an occluder
        // (a board on a wall, a desk on the floor) the contact shadow lies on the
        // occluder's side of every element, away from its midpoints, so fixed points see
        // the lamps better than the element does on average. With them the conference
        // room's direct columns delivered 100.84 % of what its lamps emit (rays shot from
        // the lamps: 100.00 %) and the room created 1.6 % light (BENCHMARKS.md).
        use rand::RngExt;
        sc.receiver.clear();
        let (ci, ni) = ei.corners(&mesh.positions);
        for t in 0..k * k {
            let u = ((t % k) as f64 + rng.random::<f64>()) / k as f64;
            let v = ((t / k) as f64 + rng.random::<f64>()) / k as f64;
            let (u, v) = self.receivers.open_uv(i as usize, u, v, || rng.random::<f64>());
            sc.receiver.push(crate::mesh::point_on(&ci, ni == 4, u, v));
        }
        let kv = self.ff.visibility_samples.max(1);
        let mut total = 0.0;
        let mut unoccluded = 0.0;
        for &x in &sc.receiver {
            let f = point_to_polygon(x, ei.normal, cj, ej.normal);
            if f <= 0.0 {
                continue;
            }
            unoccluded += f;
            stratified(kv, rng, &mut sc.vis);
            let (mut valid, mut seen) = (0u32, 0u32);
            for &(u, v) in &sc.vis {
                let y = ej.point(&mesh.positions, u, v);
                if ei.normal.dot(y - x) <= self.eps {
                    continue;
                }
                valid += 1;
                if self.rays.visible(x, ei.patch, y, ej.patch) {
                    seen += 1;
                }
            }
            if valid == 0 {
                // No sample in front of x: test the centroid of the part of j in front.
                geom::clip_halfspace(cj, |p| ei.normal.dot(p - x), self.eps, &mut sc.front);
                if sc.front.len() >= 3 {
                    let y = sc.front.iter().copied().sum::<DVec3>() / sc.front.len() as f64;
                    valid = 1;
                    seen = self.rays.visible(x, ei.patch, y, ej.patch) as u32;
                }
            }
            c.rays += valid as u64;
            if valid > 0 {
                total += f * seen as f64 / valid as f64;
            }
        }
        // In the direct columns (`exact_near`), a near pair (the finest grid) of a wholly
        // open receiver: the unoccluded factor exactly (the double contour integral), times
        // the visible share the points saw, weighted by the kernel — as point-sampled rows
        // take their near pairs. The jittered points are unbiased, but a lamp 0.01 under a
        // ceiling is a step over each ceiling element, and 9 points found it to ±10 %: the
        // lamp's direct light on the ceiling of RenderPark's closed cube `--two-sided` came
        // out 9.2 % high or 9.8 % low by the seed (`direct_columns_near_emitters` in the
        // tests). Leaf–leaf links carry reflected light, which varies slowly, and keep the
        // points (the exact factor for them made the classroom's links 60 % slower).
        if exact_near && k == self.ff.max_receiver_samples && k > 1 && unoccluded > 0.0 && self.receivers.points(i as usize, k).len() == k * k {
            let exact = super::analytic::area_factor_with(&mut sc.exact, &ci[..ni], ei.normal, cj, ej.normal) / ei.area;
            return exact * (total / unoccluded).min(1.0);
        }
        total / sc.receiver.len() as f64
    }
}

/// `f(i)` for every element `i` in parallel, as the progress stage `stage`; stops early on
/// Ctrl-C (`stopped` is set, the rest get `skipped`) and then returns `Cancelled`.
fn per_element<T: Send + Sync + Clone>(
    n: usize,
    stage: &str,
    progress: &dyn Progress,
    stopped: &AtomicBool,
    skipped: T,
    f: impl Fn(u32) -> T + Sync + Send,
) -> Result<Vec<T>> {
    progress.begin(stage, n as u64);
    let out: Vec<T> = (0..n as u32)
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            if i % 1024 == 1023 {
                progress.advance(1024);
            }
            if stopped.load(Ordering::Relaxed) || progress.should_stop() {
                stopped.store(true, Ordering::Relaxed);
                return skipped.clone();
            }
            f(i)
        })
        .collect();
    progress.end();
    if stopped.load(Ordering::Relaxed) {
        return Err(Error::Cancelled);
    }
    Ok(out)
}

/// The factor from a point to a disk of area `p` facing it at squared distance `r2`
/// (on its axis), `p / (π r² + p)`: the far-field `p / (π r²)` of a node's projected
/// area, bounded by 1 when the node is near (two nodes at the minimum size may touch).
#[inline]
fn disk_factor(p: f64, r2: f64) -> f64 {
    p / (std::f64::consts::PI * r2 + p)
}

/// The gradient in the plane with normal `n` of the values `v` at the weighted points
/// (weighted least squares about their mean `mean`; zero when they are too few or in a line
/// the gradient is taken along it).
fn plane_gradient(points: &[(DVec3, f64)], v: &[f64], n: DVec3, mean: f64) -> DVec3 {
    if points.len() < 2 {
        return DVec3::ZERO;
    }
    let c: DVec3 = points.iter().map(|(p, w)| *p * *w).sum();
    let (t, b) = crate::sampling::basis(n);
    let (mut sxx, mut sxy, mut syy, mut sxf, mut syf) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((p, w), &f) in points.iter().zip(v) {
        let d = *p - c;
        let (x, y, df) = (d.dot(t), d.dot(b), f - mean);
        sxx += w * x * x;
        sxy += w * x * y;
        syy += w * y * y;
        sxf += w * x * df;
        syf += w * y * df;
    }
    let det = sxx * syy - sxy * sxy;
    let scale = sxx + syy;
    if !(scale > 0.0) {
        return DVec3::ZERO;
    }
    if det > 1e-6 * scale * scale {
        let gx = (syy * sxf - sxy * syf) / det;
        let gy = (sxx * syf - sxy * sxf) / det;
        t * gx + b * gy
    } else {
        // Collinear points: the gradient along their line.
        let axis = (t * sxx.sqrt() + b * (sxy.signum() * syy.sqrt())).normalize_or_zero();
        let (mut sdd, mut sdf) = (0.0, 0.0);
        for ((p, w), &f) in points.iter().zip(v) {
            let d = (*p - c).dot(axis);
            sdd += w * d * d;
            sdf += w * d * (f - mean);
        }
        if sdd > 0.0 {
            axis * (sdf / sdd)
        } else {
            DVec3::ZERO
        }
    }
}


#[derive(Default)]
struct Scratch {
    values: Vec<f64>,
    points: Vec<(DVec3, f64)>,
    frontier: Vec<u32>,
    vis: Vec<(f64, f64)>,
    front: Vec<DVec3>,
    /// Receiver points of [`Ctx::leaf_factor`].
    receiver: Vec<DVec3>,
    /// The double contour integral's buffers ([`Ctx::leaf_factor`]'s near pairs).
    exact: super::analytic::Scratch,
    /// Point pairs (position, normal, polygon) of [`Ctx::terminal_factor`].
    pairs: Vec<((DVec3, DVec3, u32), (DVec3, DVec3, u32))>,
    /// Faces of a cluster receiver that see nothing of a source ([`Ctx::faces_behind`]),
    /// with their share of the link's spread once [`Ctx::behind_shares`] has set it, and the
    /// walk that finds them.
    behind: Vec<(u32, f64)>,
    behind_walk: Vec<u32>,
    /// The task's exclusions so far.
    exclusions: Vec<Exclusion>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{MaterialDesc, ObjectDesc, PolygonDesc, Scene, SceneDesc};

    /// Two unit squares (each its own polygon), meshed at `size`, and a context over them.
    fn pair(a: [DVec3; 4], b: [DVec3; 4], size: f64, test: impl FnOnce(&Ctx, u32, u32)) {
        pair_with(a, b, size, 0.0, test)
    }

    /// [`pair`] with the link tolerance's power `power_eps`.
    fn pair_with(a: [DVec3; 4], b: [DVec3; 4], size: f64, power_eps: f64, test: impl FnOnce(&Ctx, u32, u32)) {
        let scene = quads(&[a, b], false);
        ctx_for(&scene, size, power_eps, |ctx, mesh, tree| {
            // The two polygons' nodes: the root's children (one plane each).
            let [c0, c1] = tree.nodes[0].child;
            let first_is_a = mesh.elements[tree.order[tree.nodes[c0 as usize].first as usize] as usize].patch == 0;
            let (ra, rb) = if first_is_a { (c0, c1) } else { (c1, c0) };
            test(ctx, ra, rb);
        });
    }

    /// A scene of quadrilaterals, each its own object, grey ρ = 0.5 (two-sided or not).
    fn quads(qs: &[[DVec3; 4]], two_sided: bool) -> Scene {
        let mut d = SceneDesc { name: "quads".into(), ..Default::default() };
        d.materials.push(MaterialDesc { two_sided: Some(two_sided), ..MaterialDesc::diffuse("grey", Rgb::splat(0.5)) });
        for (k, v) in qs.iter().enumerate() {
            d.objects.push(ObjectDesc { name: format!("o{k}"), loc: None });
            d.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v.to_vec(), material: 0, object: k as u32, loc: None });
        }
        Scene::from_desc(d).unwrap()
    }

    /// A link context over `scene` meshed at `size` (every element open, links down to the
    /// elements), with the link tolerance's power `power_eps`.
    fn ctx_for(scene: &Scene, size: f64, power_eps: f64, test: impl FnOnce(&Ctx, &Mesh, &Tree)) {
        let mesh = crate::mesh::mesh_uniform(scene, size);
        let rays = SceneRays::new(&scene.polygons);
        let receivers = Receivers::all_open(&mesh);
        let tree = Tree::build(&mesh, &receivers.open_areas(&mesh));
        let n = tree.nodes.len();
        let opts = Options::default();
        let ff = super::super::Options::default();
        let ctx = Ctx {
            samples: Sample::of_tree(&tree, &mesh),
            tree: &tree,
            mesh: &mesh,
            rays: &rays,
            receivers: &receivers,
            ff: &ff,
            opts: &opts,
            rho: vec![0.5; n],
            b_hat: vec![1.0; n],
            light_prefix: None,
            light_prefix_x: None,
            emits: vec![false; n],
            emits_any: vec![false; n],
            lit: vec![LitFaces::NONE; n],
            sharp: true,
            power_eps,
            eps: 1e-9,
            direct: None,
            min_size: 0.0,
            reach: 0.0,
        };
        test(&ctx, &mesh, &tree);
    }

    /// A two-sided floor of two patches with an open box (no bottom) standing on the first:
    /// among the faces that reach down to the second patch B's plane (faces wholly above
    /// it are not examined for a surface source), those that see nothing of B are found,
    /// and nothing else. They are the floor's back copies (wholly in B's plane, facing
    /// away: a cluster link from B lit them by their normals), the floor's front (B in its
    /// plane) and the box's sides turned from B (B behind their plane); not the sides that
    /// face B.
    #[test]
    fn faces_that_see_nothing_of_a_floor_patch_are_found() {
        let (y0, y1) = (0.0, 0.3);
        let floor_a = [v(0.0, y0, 0.0), v(0.0, y0, 1.0), v(1.0, y0, 1.0), v(1.0, y0, 0.0)];
        let floor_b = [v(1.0, y0, 0.0), v(1.0, y0, 1.0), v(2.0, y0, 1.0), v(2.0, y0, 0.0)];
        let (lo, hi) = (0.35, 0.65);
        let top = [v(lo, y1, lo), v(lo, y1, hi), v(hi, y1, hi), v(hi, y1, lo)];
        let sides = [
            [v(lo, y0, lo), v(hi, y0, lo), v(hi, y1, lo), v(lo, y1, lo)],
            [v(hi, y0, lo), v(hi, y0, hi), v(hi, y1, hi), v(hi, y1, lo)],
            [v(hi, y0, hi), v(lo, y0, hi), v(lo, y1, hi), v(hi, y1, hi)],
            [v(lo, y0, hi), v(lo, y0, lo), v(lo, y1, lo), v(lo, y1, hi)],
        ];
        let mut qs = vec![floor_a, floor_b, top];
        qs.extend(sides);
        let scene = quads(&qs, true);
        ctx_for(&scene, 0.25, 0.0, |ctx, mesh, tree| {
            let is_floor = |e: u32| {
                let p = &scene.polygons[mesh.elements[e as usize].patch as usize];
                (p.object == 0 || p.object == 1, p.back_side, p.object == 1 && !p.back_side)
            };
            // The source: the topmost surface node holding floor B's front elements only.
            let s = (0..tree.nodes.len() as u32)
                .filter(|&k| {
                    let nd = &tree.nodes[k as usize];
                    nd.surface && (nd.first..nd.first + nd.count).all(|i| is_floor(tree.order[i as usize]).2)
                })
                .max_by_key(|&k| tree.nodes[k as usize].count)
                .unwrap();
            let mut sc = Scratch::default();
            ctx.faces_behind(0, s, 1e-6, &mut sc);
            let mut found: Vec<u32> = sc
                .behind
                .iter()
                .flat_map(|&(q, _)| {
                    let nd = &tree.nodes[q as usize];
                    (nd.first..nd.first + nd.count).map(|i| tree.order[i as usize])
                })
                .collect();
            found.sort_unstable();
            // From the polygons' own vertices, among those not wholly in front of B's plane:
            // wholly in it or behind it and not facing its way, or B wholly in their own
            // plane or behind it.
            let b_poly = scene.polygons.iter().find(|p| p.object == 1 && !p.back_side).unwrap();
            let range = |n: DVec3, c: DVec3, pts: &[DVec3]| {
                pts.iter().map(|p| n.dot(*p - c)).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| (lo.min(x), hi.max(x)))
            };
            let mut expected: Vec<u32> = (0..mesh.len() as u32)
                .filter(|&e| {
                    let p = &scene.polygons[mesh.elements[e as usize].patch as usize];
                    let (lo, hi) = range(b_poly.normal, b_poly.vertices[0], &p.vertices);
                    let behind_b = hi <= 1e-9 && p.normal.dot(b_poly.normal) < 0.999;
                    lo <= 1e-9 && (behind_b || range(p.normal, p.vertices[0], &b_poly.vertices).1 <= 1e-9)
                })
                .collect();
            expected.sort_unstable();
            let backs = (0..mesh.len() as u32).filter(|&e| is_floor(e).0 && is_floor(e).1).count();
            assert!(backs > 0 && (0..mesh.len() as u32).filter(|&e| is_floor(e).0 && is_floor(e).1).all(|e| expected.contains(&e)));
            assert!(expected.len() < mesh.len() / 2 + backs, "{} of {}", expected.len(), mesh.len());
            assert_eq!(found, expected, "faces behind floor B: {found:?}; expected: {expected:?}");
        });
    }

    fn v(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    /// The memory limit is watched while the links are refined (the check before the work
    /// is only a prediction): a limit the process already holds more than stops the links
    /// with an error naming it, where the system reports resident memory.
    #[test]
    fn links_stop_when_resident_memory_passes_the_limit() {
        if crate::transport::resident_memory().is_none() {
            eprintln!("skipping: this system does not report resident memory");
            return;
        }
        let floor = [v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(1.0, 0.0, 1.0), v(1.0, 0.0, 0.0)];
        let roof = [v(0.0, 1.0, 0.0), v(1.0, 1.0, 0.0), v(1.0, 1.0, 1.0), v(0.0, 1.0, 1.0)];
        let scene = quads(&[floor, roof], false);
        let mesh = crate::mesh::mesh_uniform(&scene, 0.25);
        let rays = SceneRays::new(&scene.polygons);
        let receivers = Receivers::all_open(&mesh);
        let run = |limit: u64| {
            let tree = Tree::build(&mesh, &receivers.open_areas(&mesh));
            let ff = super::super::Options { memory_limit: Some(limit), ..Default::default() };
            let (rho, em) = (vec![Rgb::splat(0.5); mesh.len()], vec![Rgb::ONE; mesh.len()]);
            link(&mesh, &rays, &receivers, tree, &rho, &em, &ff, &Options::default(), &crate::NoProgress)
        };
        match run(1 << 20) {
            Err(Error::TooLarge { what, needed, limit, .. }) => {
                assert!(needed > limit && limit == 1 << 20 && what.contains("while they were refined"), "{what}");
            }
            Err(e) => panic!("expected TooLarge, got {e}"),
            Ok(_) => panic!("a limit of 1 MiB did not stop the links"),
        }
        let (h, _) = run(u64::MAX).expect("no limit: linked");
        assert!(h.stats.links > 0);
    }

    #[test]
    fn terminal_factor_matches_closed_forms() {
        // Adjacent faces of a unit cube (0.200043776) and opposite ones (0.199824896).
        let floor = [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)].map(|p| p);
        let floor_up = [floor[0], floor[3], floor[2], floor[1]];
        let wall = [v(0., 0., 0.), v(0., 1., 0.), v(1., 1., 0.), v(1., 0., 0.)];
        let wall_in = [wall[0], wall[3], wall[2], wall[1]];
        let ceiling = [v(0., 1., 0.), v(1., 1., 0.), v(1., 1., 1.), v(0., 1., 1.)];
        for (name, a, b, exact) in
            [("adjacent", floor_up, wall_in, 0.200043776), ("opposite", floor_up, ceiling, 0.199824896)]
        {
            // Mesh size 0.5: few enough nodes that all open within `NEAR_BUDGET`.
            pair(a, b, 0.5, |ctx, ra, rb| {
                let mut rng = rng_for(1, 2);
                let (mut c, mut sc) = (Counts::default(), Scratch::default());
                let runs = 200;
                let mean: f64 =
                    (0..runs).map(|_| ctx.terminal_factor(ra, rb, false, false, &mut rng, &mut c, &mut sc).0).sum::<f64>()
                        / runs as f64;
                // The exact unoccluded factor at single points, through the tree (every node
                // within the near budget, so every one is opened down to its elements).
                let mut stack = Vec::new();
                for (u, w) in [(0.5, 0.5), (0.1, 0.1), (0.9, 0.02)] {
                    let x = v(u, 0.0, w);
                    let (f, _) = ctx.unoccluded_at(x, v(0., 1., 0.), rb, false, &mut stack);
                    let whole = point_to_polygon(x, v(0., 1., 0.), &b, (b[1] - b[0]).cross(b[2] - b[0]).normalize());
                    assert!((f - whole).abs() < 1e-9, "{name} at {x:?}: {f} through the tree, {whole} for the polygon");
                }
                assert!((mean / exact - 1.0).abs() < 0.03, "{name}: terminal factor {mean:.5}, exact {exact:.5}");
            });
        }
    }

    /// The quick estimate of a terminal link (a quarter of its point pairs) is chosen before
    /// any ray, not by the quick draw itself: with the link tolerance at the pair's own
    /// power, choosing by the draw keeps the low draws and draws the high ones again, and
    /// the mean factor of two adjacent faces came out 4 % low (0.1920 for 0.2000 with the
    /// tolerance at 0.8 × the link's power).
    #[test]
    fn terminal_factor_is_unbiased_at_the_link_tolerance() {
        let floor_up = [v(0., 0., 0.), v(0., 0., 1.), v(1., 0., 1.), v(1., 0., 0.)];
        let wall_in = [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)];
        let exact = 0.200043776;
        // Power of the link: F · A_R · ρ · B̂ = F · 1 · 0.5 · 1.
        for eps in [0.8, 1.0, 1.2].map(|k| k * exact * 0.5) {
            pair_with(floor_up, wall_in, 0.5, eps, |ctx, ra, rb| {
                let mut rng = rng_for(7, 3);
                let (mut c, mut sc) = (Counts::default(), Scratch::default());
                let minor = ctx.minor(ra, rb, separation_ratio(ctx.node(ra), ctx.node(rb)), &mut sc);
                let runs = 4000;
                let mean: f64 = (0..runs).map(|_| ctx.terminal_factor(ra, rb, false, minor, &mut rng, &mut c, &mut sc).0).sum::<f64>() / runs as f64;
                assert!((mean / exact - 1.0).abs() < 0.02, "link tolerance {eps}: terminal factor {mean:.5}, exact {exact:.5}");
            });
        }
    }
}

/// `F·x` estimated by rays, matrix-free: per element, `m` cosine-distributed rays from its
/// open points ([`hemisphere_rays`], stream drawn from `seed`), each reading `x` of the
/// element it meets (nothing for a ray that leaves or meets the back of a one-sided
/// face). An unbiased yardstick for an operator's gather (the final gather does the same
/// per pixel); NaN for an element with no open point.
pub fn gather_by_rays(
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    x: &[crate::Rgb],
    m: usize,
    seed: u64,
) -> Vec<crate::Rgb> {
    let locator = crate::mesh::Locator::new(mesh);
    let (lo, hi) = geom::bounds_3d(&mesh.positions);
    let eps = 1e-7 * (hi - lo).length().max(f64::MIN_POSITIVE);
    (0..mesh.elements.len())
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            let mut sum = crate::Rgb::ZERO;
            let cast = hemisphere_rays(mesh, rays, receivers, seed, m, eps, i, |p, dir, hit| {
                if let Some(j) = locator.front_hit(mesh, rays, p, dir, hit) {
                    sum += x[j as usize];
                }
            });
            if cast {
                sum * (1.0 / m as f64)
            } else {
                crate::Rgb::splat(f64::NAN)
            }
        })
        .collect()
}
