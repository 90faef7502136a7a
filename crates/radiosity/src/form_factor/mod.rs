//! Stage 4a: form factors — how much of the energy leaving element `i` reaches element `j`.
//!
//! ```text
//! F_ij = 1/A_i ∫_{A_i} ∫_{A_j} cosθ_i cosθ_j / (π r²) · V(x, y) dA_y dA_x
//! ```
//!
//! (Goral, Torrance, Greenberg & Battaile 1984; Cohen & Wallace 1993, ch. 4). Every method
//! is a runtime choice ([`Method`]) and produces the same thing: the rows of `F`, one
//! element at a time, in f64 ([`for_each_row`], used by the view-factor tool) or collected
//! as the solver's [`SparseRows`] in f32 ([`compute`], used by render/solve).
//!
//! Methods (one file each):
//! - [`Method::Hemicube`] — item buffer on the five faces of a hemicube at each element's
//!   centre, with exact delta form factors (Cohen & Greenberg 1985).
//! - [`Method::Analytic`] — exact polygon-to-polygon factor by the double contour integral,
//!   no occlusion (Schröder & Hanrahan 1993).
//! - [`Method::PointSampled`] — the differential-area-to-polygon factor by the contour
//!   integral ([`analytic::point_factor`]) at stratified points of the receiver, times the visible fraction
//!   from ray-sampled points of the source (Wallace, Elmquist & Haines 1989).
//! - [`Method::MonteCarlo`] — cosine-weighted rays from stratified points of the sender,
//!   closest hit (e.g. Cohen & Wallace 1993 §4.10).
//! - [`Method::Adaptive`] — the point-to-polygon factor to the *visible part* of the
//!   receiver (occluders' shadows cut out exactly), integrated over the sender by adaptive
//!   subdivision to a tolerance (after Walton 2002, the View3D method).
//!
//! Conventions: surfaces are one-sided (front by vertex order, right-hand rule); every
//! polygon blocks rays from both sides; a factor counts only what arrives on the front of
//! the receiver. Random streams are `(seed, row)`, so results do not depend on the number
//! of threads. [`diagnostics`] measures reciprocity and closure; [`enclosure`] enforces
//! them for a closed geometry.

pub mod adaptive;
pub mod analytic;
pub mod diagnostics;
mod emitter_tree;
pub mod enclosure;
pub mod hemicube;
pub mod hierarchical;
pub mod monte_carlo;
pub mod sparse;
mod occluders;
mod point_sampled;
mod twins;

use std::str::FromStr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::accel::SceneRays;
use crate::geom::{self, kernel};
use crate::mesh::coverage::MAX_K;
use crate::mesh::{Mesh, Receivers};
use crate::scene::Scene;
use crate::transport::SparseRows;
use crate::{Error, Progress, Result};

/// A form-factor method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Hemicube item buffer with delta form factors (Cohen & Greenberg 1985).
    Hemicube,
    /// Exact unoccluded polygon-to-polygon contour integral (Schröder & Hanrahan 1993).
    Analytic,
    /// Point-to-polygon analytic factor times ray-sampled visibility (Wallace et al. 1989).
    PointSampled,
    /// Cosine-weighted rays from stratified points of the sender.
    MonteCarlo,
    /// Adaptive integration of the exactly shadowed point-to-polygon factor (Walton 2002).
    Adaptive,
}

impl Method {
    /// Every method, in documentation order.
    pub const ALL: [Method; 5] =
        [Method::Hemicube, Method::Analytic, Method::PointSampled, Method::MonteCarlo, Method::Adaptive];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Hemicube => "hemicube",
            Method::Analytic => "analytic",
            Method::PointSampled => "point-sampled",
            Method::MonteCarlo => "monte-carlo",
            Method::Adaptive => "adaptive",
        }
    }

    /// How far above 1 a raw row may sum from the method's own error alone (its stated
    /// accuracy: point sampling 0.5 %, the hemicube 1 %, rays and exact integration
    /// rounding): rows beyond it are counted as corrected by the [`RowGuard`].
    pub fn row_sum_slack(self) -> f64 {
        match self {
            Method::PointSampled => 5e-3,
            Method::Hemicube => 1e-2,
            Method::Adaptive => 1e-4,
            Method::MonteCarlo | Method::Analytic => 1e-9,
        }
    }

    /// True for the methods that integrate over whole sender and receiver areas to their
    /// own accuracy (analytic, adaptive): these need no subdivision of the input polygons.
    pub fn is_area_to_area(self) -> bool {
        matches!(self, Method::Analytic | Method::Adaptive)
    }
}

impl FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::ALL.iter().copied().find(|m| m.name() == s).ok_or_else(|| {
            let names: Vec<_> = Method::ALL.iter().map(|m| m.name()).collect();
            Error::Invalid(format!("unknown form-factor method '{s}' (known: {})", names.join(", ")))
        })
    }
}

/// Options shared by the methods (each uses those that apply to it).
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// The method.
    pub method: Method,
    /// Seed of every random choice; results do not depend on the thread count.
    pub seed: u64,
    /// Point-sampled: visibility rays per receiver point, as `n × n` stratified points on
    /// the source.
    pub visibility_samples: usize,
    /// Point-sampled: largest number of receiver points per side (`n × n`, at most
    /// [`crate::mesh::coverage::MAX_K`]), used for close pairs.
    pub max_receiver_samples: usize,
    /// Hemicube: pixels along the top face (the four side faces are `res × res/2`).
    pub hemicube_resolution: usize,
    /// Monte Carlo: rays per sender element (rounded up to a square number).
    pub mc_rays: usize,
    /// Adaptive: relative tolerance of each factor (the integration stops when its error
    /// estimate is below `tolerance × F_ij`, or below `tolerance × 1e-3` absolute).
    pub adaptive_tolerance: f64,
    /// Adaptive: largest number of integrand evaluations per element pair.
    pub adaptive_max_evaluations: usize,
    /// Adaptive: integrate numerically even for pairs with no possible occluder (which
    /// otherwise take the exact contour integral). For validating the integration.
    pub adaptive_always_integrate: bool,
    /// Memory limit in bytes: what the collected rows may use, or on the hierarchical
    /// transport the whole run's predicted peak resident memory, watched again while the
    /// links are refined (None: what the system has available; see
    /// [`crate::form_factor::hierarchical::predict_peak`]).
    pub memory_limit: Option<u64>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            method: Method::PointSampled,
            seed: 0,
            visibility_samples: 1,
            max_receiver_samples: 3,
            hemicube_resolution: hemicube::DEFAULT_RESOLUTION,
            mc_rays: monte_carlo::DEFAULT_RAYS,
            adaptive_tolerance: adaptive::DEFAULT_TOLERANCE,
            adaptive_max_evaluations: adaptive::DEFAULT_MAX_EVALUATIONS,
            adaptive_always_integrate: false,
            memory_limit: None,
        }
    }
}

impl Options {
    /// Checks the values (non-zero counts, a positive tolerance, an even hemicube size).
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(m));
        if self.visibility_samples == 0 || self.visibility_samples > 64 {
            return bad(format!("visibility samples must be between 1 and 64, got {}", self.visibility_samples));
        }
        if self.max_receiver_samples == 0 || self.max_receiver_samples > MAX_K {
            return bad(format!("receiver samples must be between 1 and {MAX_K}, got {}", self.max_receiver_samples));
        }
        if self.hemicube_resolution < 2 || self.hemicube_resolution > 8192 || self.hemicube_resolution % 2 != 0 {
            return bad(format!("hemicube resolution must be even and between 2 and 8192, got {}", self.hemicube_resolution));
        }
        if self.mc_rays == 0 || self.mc_rays > 1 << 30 {
            return bad(format!("Monte Carlo rays must be between 1 and 2^30, got {}", self.mc_rays));
        }
        if !(self.adaptive_tolerance > 0.0 && self.adaptive_tolerance < 1.0) {
            return bad(format!("adaptive tolerance must be in (0, 1), got {}", self.adaptive_tolerance));
        }
        if self.adaptive_max_evaluations < 100 {
            return bad("adaptive evaluations must be at least 100".into());
        }
        Ok(())
    }
}

/// What a form-factor computation did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Stats {
    /// Method name.
    pub method: String,
    /// Element pairs with a non-zero factor.
    pub nonzeros: u64,
    /// Visibility rays cast.
    pub rays: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Things the user should know about the result (e.g. occlusion ignored).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// What the row guard had to correct (see [`RowGuard`]).
    pub guard: RowGuard,
    /// The hierarchical operator's links and nodes (`--transport hierarchical`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hierarchy: Option<crate::transport::hierarchical::HierarchyStats>,
}

/// The guard behind every method: each row leaves the method with every `F_ij` finite
/// and positive and `Σ_j F_ij ≤ 1`, so `B = E + ρFB` is a contraction (`‖ρF‖∞ < 1`) and no
/// radiosity can exceed the furnace bound `max E / (1 − max ρ)` on any geometry. A raw row
/// that breaks this (sampling near coincident or touching surfaces, rounding) is repaired —
/// non-finite and negative entries dropped, a sum above 1 scaled to 1 — and counted here.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RowGuard {
    /// Rows whose sum exceeded 1 by more than the method's own tolerance
    /// ([`Method::row_sum_slack`]); every row above 1 is scaled to 1, these are counted.
    pub rows_corrected: u64,
    /// Entries dropped because they were NaN, infinite or negative.
    pub entries_dropped: u64,
    /// The largest raw row sum met (before correction).
    pub max_row_sum: f64,
    /// The row (element or polygon) with that sum.
    pub worst_row: Option<usize>,
    /// Where that row's source polygon was defined, filled in by the caller that knows
    /// the geometry (e.g. `cube.obj:12`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worst_source: Option<String>,
    /// How far above 1 a row may be before it counts as corrected (the method's tolerance).
    #[serde(skip)]
    pub slack: f64,
}


impl RowGuard {
    /// Repairs row `i` in place (see the type's docs).
    pub fn check(&mut self, i: usize, row: &mut Vec<(u32, f64)>) {
        let before = row.len();
        row.retain(|e| e.1.is_finite() && e.1 >= 0.0);
        self.entries_dropped += (before - row.len()) as u64;
        let sum: f64 = row.iter().map(|e| e.1).sum();
        if sum > self.max_row_sum || self.worst_row.is_none() {
            self.max_row_sum = sum;
            self.worst_row = Some(i);
        }
        if sum > 1.0 {
            if sum > 1.0 + self.slack {
                self.rows_corrected += 1;
            }
            for e in row.iter_mut() {
                e.1 /= sum;
            }
        }
    }

    /// Fills [`RowGuard::worst_source`] when the rows are `mesh`'s elements: the file and
    /// line of the worst element's source polygon.
    pub fn locate_element(&mut self, scene: &Scene, mesh: &Mesh) {
        self.worst_source = self.worst_row.and_then(|i| mesh.elements.get(i)).and_then(|e| scene.polygons[e.patch as usize].loc.as_ref()).map(|l| l.to_string());
    }

    /// The worst row and, when known, its source: `"12 (polygon at cube.obj:3)"`.
    pub fn worst_place(&self) -> String {
        let at = self.worst_source.as_deref().map(|s| format!(" (polygon at {s})")).unwrap_or_default();
        format!("{}{at}", self.worst_row.unwrap_or(0))
    }

    /// A warning for the user when something was corrected.
    pub fn warning(&self) -> Option<String> {
        if self.rows_corrected == 0 && self.entries_dropped == 0 {
            return None;
        }
        Some(format!(
            "form factors: {} row(s) summed above 1 and were scaled to 1, {} non-finite or negative entries dropped; \
             largest raw row sum {:.4} at row {}; this happens near coincident, touching or interpenetrating surfaces",
            self.rows_corrected,
            self.entries_dropped,
            self.max_row_sum,
            self.worst_place()
        ))
    }
}

/// Computes the form-factor rows of all elements of `mesh`, for the radiosity solvers
/// (f32 sparse rows; entries ≤ 0 are dropped).
///
/// The solvers use the *open* part of each element ([`Receivers`]: points inside closed
/// geometry, such as floor under a box, are excluded). Point-sampled gathers at open points
/// and the hemicube stands on the element's open representative point; Monte Carlo and
/// adaptive integrate over the whole element, where covered parts see nothing, so their
/// rows are divided by the element's open fraction to give the factor of its open part.
pub fn compute(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    opts: &Options,
    progress: &dyn Progress,
) -> Result<(SparseRows, Stats)> {
    check_row_memory(scene, mesh, opts)?;
    let mut rows: Vec<Vec<(u32, f32)>> = Vec::with_capacity(mesh.len());
    let stats = for_each_row(scene, mesh, rays, receivers, opts, None, progress, &mut |_, row| {
        rows.push(row.iter().filter(|e| e.1 > 0.0).map(|&(j, f)| (j, f as f32)).collect());
        Ok(())
    })?;
    let rows = SparseRows::from_rows(rows);
    let stats = Stats { nonzeros: rows.nnz() as u64, ..stats };
    Ok((rows, stats))
}

/// Computes the rows of the elements `which` (all elements, in order, when None) and
/// hands each to `sink` as `(i, entries)`, in the order of `which`. Entries are `(j, F_ij)`
/// with `F_ij ≠ 0`, columns ascending, in f64. Rows are computed in parallel blocks but
/// delivered in order, so a caller can stream them to a file.
#[allow(clippy::too_many_arguments)]
pub fn for_each_row(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    opts: &Options,
    which: Option<&[u32]>,
    progress: &dyn Progress,
    sink: &mut dyn FnMut(usize, &[(u32, f64)]) -> Result<()>,
) -> Result<Stats> {
    opts.validate()?;
    let t0 = Instant::now();
    let mut warnings = Vec::new();
    let all: Vec<u32>;
    let which = match which {
        Some(w) => w,
        None => {
            all = (0..mesh.len() as u32).collect();
            &all
        }
    };
    let ctx = Context::new(scene, mesh, rays, receivers, opts);
    let (nonzeros, nrays, mut guard) = match opts.method {
        Method::Hemicube => drive(&hemicube::Rows::new(&ctx), which, opts.method.row_sum_slack(), progress, sink)?,
        Method::Analytic => {
            warn_occlusion(scene, progress, &mut warnings);
            drive(&analytic_rows::Rows::new(&ctx), which, opts.method.row_sum_slack(), progress, sink)?
        }
        Method::PointSampled => drive(&point_sampled::Rows::new(&ctx), which, opts.method.row_sum_slack(), progress, sink)?,
        Method::MonteCarlo => drive(&monte_carlo::Rows::new(&ctx), which, opts.method.row_sum_slack(), progress, sink)?,
        Method::Adaptive => {
            let rows = adaptive::Rows::new(&ctx);
            let r = drive(&rows, which, opts.method.row_sum_slack(), progress, sink)?;
            let area: f64 = which.iter().map(|&i| mesh.elements[i as usize].area).sum();
            push_warning(rows.budget_warning(area), progress, &mut warnings);
            r
        }
    };
    guard.locate_element(scene, mesh);
    guard_warning(&guard, progress, &mut warnings);
    Ok(Stats {
        method: opts.method.name().to_string(),
        nonzeros,
        rays: nrays,
        seconds: t0.elapsed().as_secs_f64(),
        warnings,
        guard,
        hierarchy: None,
    })
}

/// As [`for_each_row`] for the area-to-area methods (analytic, adaptive) over the scene's
/// polygons themselves, unmeshed (any number of vertices): row `p` holds `(q, F_pq)` for
/// every polygon `q`. Used for per-object matrices, where these methods need no elements.
pub fn for_each_polygon_row(
    scene: &Scene,
    rays: &SceneRays,
    opts: &Options,
    which: Option<&[u32]>,
    progress: &dyn Progress,
    sink: &mut dyn FnMut(usize, &[(u32, f64)]) -> Result<()>,
) -> Result<Stats> {
    opts.validate()?;
    if !opts.method.is_area_to_area() {
        return Err(Error::Invalid(format!("{} form factors need elements, not whole polygons", opts.method.name())));
    }
    let t0 = Instant::now();
    let all: Vec<u32>;
    let which = match which {
        Some(w) => w,
        None => {
            all = (0..scene.polygons.len() as u32).collect();
            &all
        }
    };
    let mesh = Mesh::default();
    let receivers = Receivers::default();
    let ctx = Context::new(scene, &mesh, rays, &receivers, opts);
    let mut warnings = Vec::new();
    let (nonzeros, nrays, mut guard) = if opts.method == Method::Analytic {
        warn_occlusion(scene, progress, &mut warnings);
        drive(&analytic_rows::PolygonRows::new(&ctx), which, opts.method.row_sum_slack(), progress, sink)?
    } else {
        let rows = adaptive::PolygonRows::new(&ctx);
        let r = drive(&rows, which, opts.method.row_sum_slack(), progress, sink)?;
        let area: f64 = which.iter().map(|&p| scene.polygons[p as usize].area).sum();
        push_warning(rows.budget_warning(area), progress, &mut warnings);
        r
    };
    if let Some(p) = guard.worst_row {
        guard.worst_source = scene.polygons.get(p).and_then(|p| p.loc.as_ref()).map(|l| l.to_string());
    }
    guard_warning(&guard, progress, &mut warnings);
    Ok(Stats { method: opts.method.name().to_string(), nonzeros, rays: nrays, seconds: t0.elapsed().as_secs_f64(), warnings, guard, hierarchy: None })
}

fn guard_warning(guard: &RowGuard, progress: &dyn Progress, warnings: &mut Vec<String>) {
    push_warning(guard.warning(), progress, warnings);
}

/// Shows `w` (if any) and keeps it for the report.
pub(crate) fn push_warning(w: Option<String>, progress: &dyn Progress, warnings: &mut Vec<String>) {
    if let Some(w) = w {
        progress.warning(&w);
        warnings.push(w);
    }
}

fn warn_occlusion(scene: &Scene, progress: &dyn Progress, warnings: &mut Vec<String>) {
    if let Some(why) = possible_occlusion(scene) {
        let w = format!(
            "analytic form factors ignore occlusion, and this scene can occlude ({why}); \
             use adaptive, monte-carlo, point-sampled or hemicube for occluded factors"
        );
        push_warning(Some(w), progress, warnings);
    }
}

/// What every method sees.
pub(crate) struct Context<'a> {
    pub scene: &'a Scene,
    pub mesh: &'a Mesh,
    pub rays: &'a SceneRays,
    /// Open receiver points of the elements (point-sampled, hemicube).
    pub receivers: &'a Receivers,
    pub opts: &'a Options,
    /// Per patch: (a point of its plane, unit normal).
    pub planes: Vec<(DVec3, DVec3)>,
    /// Per patch: the lower-numbered coincident same-facing patches that overlap it and
    /// own the overlap ([`twins::coincident_twins`]; point-sampled, hemicube and adaptive use it).
    pub twins: Vec<Vec<u32>>,
    /// Per patch: how far its vertices may lie from its plane (the planarity tolerance
    /// that input polygons are accepted with, on its size, plus `eps`).
    pub flatness: Vec<f64>,
    /// Distance below which a point counts as on a plane.
    pub eps: f64,
}

impl<'a> Context<'a> {
    fn new(scene: &'a Scene, mesh: &'a Mesh, rays: &'a SceneRays, receivers: &'a Receivers, opts: &'a Options) -> Self {
        let planes = scene.polygons.iter().map(|p| (p.vertices[0], p.normal)).collect();
        let eps = 1e-9 * scene.diagonal();
        let flatness = scene
            .polygons
            .iter()
            .map(|p| {
                let (lo, hi) = p.vertices.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
                2.0 * crate::scene::PLANARITY_TOL * (hi - lo).length() + eps
            })
            .collect();
        let twins = twins::coincident_twins(&scene.polygons, 1e-7 * scene.diagonal());
        Context { scene, mesh, rays, receivers, opts, planes, twins, flatness, eps }
    }

    /// Patches that can exchange light with patch `pi` at all: some vertex in front of
    /// pi's plane and some vertex of pi in front of theirs.
    pub fn facing_patches(&self, pi: u32, out: &mut Vec<u32>) {
        out.clear();
        let (ci, ni) = self.planes[pi as usize];
        let poly_i = &self.scene.polygons[pi as usize];
        for (q, poly) in self.scene.polygons.iter().enumerate() {
            if q as u32 == pi {
                continue;
            }
            let (cq, nq) = self.planes[q];
            // Back to back in one plane (the two sides of a two-sided polygon, or a wall's
            // two faces): no exchange. Checked with the planarity tolerance, since the
            // copies of a slightly warped quad lie up to that far in front of each other,
            // which made each see the other as a whole hemisphere (office2's chair legs:
            // raw row sums of 2, issue 9).
            let tol = self.flatness[pi as usize].max(self.flatness[q]);
            if nq.dot(ni) < -1.0 + 1e-9 && poly.vertices.iter().all(|v| ni.dot(*v - ci).abs() <= tol) {
                continue;
            }
            let q_in_front = poly.vertices.iter().any(|v| ni.dot(*v - ci) > self.eps);
            if q_in_front && poly_i.vertices.iter().any(|v| nq.dot(*v - cq) > self.eps) {
                out.push(q as u32);
            }
        }
    }

    /// Corners of element `e`.
    #[inline]
    pub fn corners(&self, e: usize) -> ([DVec3; 4], usize) {
        self.mesh.elements[e].corners(&self.mesh.positions)
    }
}

/// Settles a row whose near entries were made exact (point-sampled and hemicube rows):
/// `row` holds (column, factor, far, far weight `(s_i / d_ij)²`), and `excess` is what the
/// near entries gained over the point estimate that the far field was measured against.
/// The far entries give it up (or take it, when negative) in proportion to
/// `F_ij (s_i / d_ij)²`, each by at most its own factor: the difference between an
/// element's mean and its centre value is a second-order term, so nearer parts of the far
/// field give it up and a distant light barely does (a uniform scale would dim direct
/// light near every corner). Then, should the row exceed one (no point sees more than its
/// hemisphere), the far entries give way.
pub(crate) fn settle_far_field(row: &mut [(u32, f64, bool, f64)], excess: f64) {
    let wsum: f64 = row.iter().filter(|e| e.2).map(|e| e.1 * e.3).sum();
    if wsum > 0.0 {
        for e in row.iter_mut().filter(|e| e.2) {
            e.1 *= (1.0 - excess * e.3 / wsum).clamp(0.0, 2.0);
        }
    }
    let (near, far) = row.iter().fold((0.0, 0.0), |(n, f), e| if e.2 { (n, f + e.1) } else { (n + e.1, f) });
    if near + far > 1.0 && far > 0.0 {
        let k = ((1.0 - near) / far).max(0.0);
        for e in row.iter_mut().filter(|e| e.2) {
            e.1 *= k;
        }
    }
}

/// One method's per-row work.
pub(crate) trait RowSource: Sync {
    /// Per-thread buffers.
    type Scratch: Send;
    /// Fresh buffers.
    fn scratch(&self) -> Self::Scratch;
    /// Appends `(j, F_ij)` for the non-zero factors of row `i` (any order, each `j` once)
    /// and returns the number of rays cast.
    fn row(&self, i: usize, s: &mut Self::Scratch, out: &mut Vec<(u32, f64)>) -> u64;
}

/// Rows computed per parallel block before they are handed on in order.
const BLOCK: usize = 256;

fn drive<R: RowSource>(
    src: &R,
    which: &[u32],
    slack: f64,
    progress: &dyn Progress,
    sink: &mut dyn FnMut(usize, &[(u32, f64)]) -> Result<()>,
) -> Result<(u64, u64, RowGuard)> {
    progress.begin("form factors", which.len() as u64);
    let mut guard = RowGuard { slack, ..Default::default() };
    let rays = AtomicU64::new(0);
    let stopped = AtomicBool::new(false);
    let mut nonzeros = 0u64;
    for block in which.chunks(BLOCK) {
        let rows: Vec<Vec<(u32, f64)>> = block
            .par_iter()
            .map_init(
                || (src.scratch(), Vec::new()),
                |(s, buf), &i| {
                    if stopped.load(Ordering::Relaxed) {
                        return Vec::new();
                    }
                    if progress.should_stop() {
                        stopped.store(true, Ordering::Relaxed);
                        return Vec::new();
                    }
                    buf.clear();
                    let r = src.row(i as usize, s, buf);
                    rays.fetch_add(r, Ordering::Relaxed);
                    progress.advance(1);
                    let mut v = buf.clone();
                    v.sort_unstable_by_key(|e| e.0);
                    v
                },
            )
            .collect();
        if stopped.load(Ordering::Relaxed) {
            progress.end();
            return Err(Error::Cancelled);
        }
        for (&i, mut r) in block.iter().zip(rows) {
            guard.check(i as usize, &mut r);
            nonzeros += r.len() as u64;
            sink(i as usize, &r)?;
        }
    }
    progress.end();
    Ok((nonzeros, rays.load(Ordering::Relaxed), guard))
}

/// Why some polygon could hide part of another from a third, or None for a convex scene
/// (no vertex strictly behind another polygon's plane: the faces of a convex room, two
/// facing plates ...), where nothing can be occluded: a polygon `q` meeting the open
/// segment between points of `p` and `r` would need points on both sides of its own plane
/// or the segment to lie in it. Polygons back to back count as possibly occluding.
pub fn possible_occlusion(scene: &Scene) -> Option<String> {
    use rayon::prelude::*;
    let eps = 1e-9 * scene.diagonal();
    let polys = &scene.polygons;
    // n² tests when nothing can occlude (the case that matters), in parallel; the first
    // witness in polygon order, so the message does not depend on the threads.
    polys.par_iter().enumerate().find_map_first(|(pi, p)| {
        let c = p.vertices[0];
        polys
            .iter()
            .enumerate()
            .find(|(qi, q)| *qi != pi && q.vertices.iter().any(|v| p.normal.dot(*v - c) < -eps))
            .map(|(qi, _)| format!("polygon {qi} has a vertex behind the plane of polygon {pi}"))
    })
}

/// Fails with [`Error::TooLarge`] when the collected rows could not fit in memory. The
/// bound counts, for every element, the elements of the patches it faces (occlusion
/// ignored), at 8 bytes per stored entry; it is only evaluated when the crude `n²` bound
/// is over the limit, and skipped for more than 50,000 patches (too slow to bound).
fn check_row_memory(scene: &Scene, mesh: &Mesh, opts: &Options) -> Result<()> {
    let limit = match opts.memory_limit.or_else(crate::transport::available_memory) {
        Some(l) => l,
        None => return Ok(()),
    };
    let n = mesh.len() as u64;
    if n * n * 8 <= limit || scene.polygons.len() > 50_000 {
        return Ok(());
    }
    let rays = SceneRays::default();
    let receivers = Receivers::default();
    let ctx = Context::new(scene, mesh, &rays, &receivers, opts);
    let mut list = Vec::new();
    let mut entries = 0u64;
    for (p, pe) in mesh.patches.iter().enumerate() {
        ctx.facing_patches(p as u32, &mut list);
        let cols: u64 = list.iter().map(|&q| mesh.patches[q as usize].count as u64).sum();
        entries += pe.count as u64 * cols;
    }
    let needed = entries * 8 + n * 8;
    if needed > limit {
        return Err(Error::TooLarge {
            what: format!("the form-factor rows of {n} elements"),
            needed,
            limit,
            hint: "use a larger mesh size".into(),
        });
    }
    Ok(())
}

/// The analytic method as rows over mesh elements.
mod analytic_rows {
    use super::analytic::{area_factor_with, Scratch};
    use super::{Context, RowSource};

    pub(crate) struct Rows<'a> {
        ctx: &'a Context<'a>,
    }

    impl<'a> Rows<'a> {
        pub fn new(ctx: &'a Context<'a>) -> Self {
            Rows { ctx }
        }
    }

    impl RowSource for Rows<'_> {
        type Scratch = (Scratch, Vec<u32>, u32);
        fn scratch(&self) -> Self::Scratch {
            (Scratch::default(), Vec::new(), u32::MAX)
        }
        fn row(&self, i: usize, s: &mut Self::Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
            let (scratch, patches, cached) = s;
            let mesh = self.ctx.mesh;
            let ei = &mesh.elements[i];
            if *cached != ei.patch {
                *cached = ei.patch;
                self.ctx.facing_patches(ei.patch, patches);
            }
            let (ci, ni) = self.ctx.corners(i);
            for &q in patches.iter() {
                let pe = mesh.patches[q as usize];
                for j in pe.first..pe.first + pe.count {
                    let ej = &mesh.elements[j as usize];
                    let (cj, nj) = self.ctx.corners(j as usize);
                    let af = area_factor_with(scratch, &ci[..ni], ei.normal, &cj[..nj], ej.normal);
                    if af != 0.0 {
                        out.push((j, af / ei.area));
                    }
                }
            }
            0
        }
    }

    /// Analytic rows over whole polygons.
    pub(crate) struct PolygonRows<'a> {
        ctx: &'a Context<'a>,
    }

    impl<'a> PolygonRows<'a> {
        pub fn new(ctx: &'a Context<'a>) -> Self {
            PolygonRows { ctx }
        }
    }

    impl RowSource for PolygonRows<'_> {
        type Scratch = (Scratch, Vec<u32>);
        fn scratch(&self) -> Self::Scratch {
            (Scratch::default(), Vec::new())
        }
        fn row(&self, p: usize, s: &mut Self::Scratch, out: &mut Vec<(u32, f64)>) -> u64 {
            let (scratch, patches) = s;
            self.ctx.facing_patches(p as u32, patches);
            let polys = &self.ctx.scene.polygons;
            let pp = &polys[p];
            for &q in patches.iter() {
                let pq = &polys[q as usize];
                let af = area_factor_with(scratch, &pp.vertices, pp.normal, &pq.vertices, pq.normal);
                if af != 0.0 {
                    out.push((q, af / pp.area));
                }
            }
            0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{builtin, Scene};

    #[test]
    fn method_names_round_trip() {
        for m in Method::ALL {
            assert_eq!(m.name().parse::<Method>().unwrap(), m);
        }
        assert!("radiance".parse::<Method>().is_err());
    }

    #[test]
    fn convex_scenes_cannot_occlude() {
        let furnace = Scene::from_desc(builtin::furnace(0.5, 1.0)).unwrap();
        assert!(possible_occlusion(&furnace).is_none());
        let cornell = Scene::from_desc(builtin::cornell()).unwrap();
        assert!(possible_occlusion(&cornell).is_some());
    }
}
