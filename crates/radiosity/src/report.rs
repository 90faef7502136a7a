//! The JSON report: what was computed, how well, and how long it took.

use serde::Serialize;

use crate::form_factor;
use crate::solve::{EnergyBalance, SolveStats};

/// Per-object result.
#[derive(Clone, Debug, Serialize)]
pub struct ObjectReport {
    /// Object name (OBJ `o`/`g`, glTF node/mesh; `#k` for repeated names).
    pub name: String,
    /// Area in scene units² (one side).
    pub area: f64,
    /// Area-averaged radiosity B (exitance), RGB.
    pub radiosity_rgb: [f64; 3],
    /// Area-averaged outgoing radiance L = B/π, RGB.
    pub radiance_rgb: [f64; 3],
    /// Two-sided objects: the back side's mean radiosity (the fields above are the front
    /// side, the input winding).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub back_radiosity_rgb: Option<[f64; 3]>,
    /// Two-sided objects: the back side's mean radiance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub back_radiance_rgb: Option<[f64; 3]>,
    /// Number of elements.
    pub elements: usize,
    /// Material names used.
    pub materials: Vec<String>,
}

/// Seconds per pipeline stage.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Timings {
    /// Reading and validating the scene.
    pub load: f64,
    /// Meshing.
    pub mesh: f64,
    /// Building the ray-casting hierarchy.
    pub bvh: f64,
    /// Form factors.
    pub form_factors: f64,
    /// Direct light from the sky, its sun and the point, spot and directional lights per
    /// element (scenes with such light).
    pub sky: f64,
    /// Solving.
    pub solve: f64,
    /// Per-vertex reconstruction.
    pub reconstruct: f64,
    /// Rendering all images.
    pub render: f64,
    /// Whole run.
    pub total: f64,
    /// Every stage that reported progress, in order, with its seconds (the hierarchy's
    /// coverage, closure, direct light, links and ray rows; the form-factor rows; the final
    /// gather ...), as the command line's progress saw them.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<StageTime>,
}

/// One stage's wall time ([`Timings::stages`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageTime {
    /// The stage, as named to [`crate::Progress::begin`].
    pub stage: String,
    /// Wall seconds from its begin to its end.
    pub seconds: f64,
}

/// Energy bookkeeping (power per RGB channel, scene units): emitted = absorbed + escaped +
/// unshot, in the formulation of the solver that produced it ([`EnergyBalance`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct EnergyReport {
    /// Emitted power Σ A_i E_i.
    pub emitted: [f64; 3],
    /// Absorbed by the surfaces.
    pub absorbed: [f64; 3],
    /// Left through openings (open scenes).
    pub escaped: [f64; 3],
    /// Absorbed by the back faces of one-sided surfaces (a winding problem when large).
    pub back_faces: [f64; 3],
    /// Received but not yet passed on (unshot power; for gathering solvers the residual).
    pub unshot: [f64; 3],
    /// max over channels of |emitted − absorbed − escaped − back_faces − unshot| / emitted.
    pub imbalance: f64,
    /// Under a sky or with point, spot or directional lights: their power reaching the
    /// surfaces directly, Σ H_ext,i·A_i. Its first reflection (ρ times it) is part of
    /// `emitted`: the system's sources are the surfaces' own emission plus that reflection.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub external_incident: Option<[f64; 3]>,
    /// With point or spot lights: the power they send out, Σ 4π I (spots: over their cone).
    /// In a closed room all of it reaches the surfaces (`external_incident`, without a sky).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lights_power: Option<[f64; 3]>,
}

impl From<&EnergyBalance> for EnergyReport {
    fn from(e: &EnergyBalance) -> Self {
        EnergyReport {
            emitted: e.emitted.to_array(),
            absorbed: e.absorbed.to_array(),
            escaped: e.escaped.to_array(),
            back_faces: e.back_faces.to_array(),
            unshot: e.unshot.to_array(),
            imbalance: e.relative_imbalance(),
            external_incident: None,
            lights_power: None,
        }
    }
}

/// One solver's line in the comparison of `solve --solver all`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ComparisonRow {
    /// Solver name.
    pub solver: String,
    /// Why it has no result (refused as too large, skipped), if so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Solver seconds until the residual was first at most 1e-3.
    #[serde(rename = "seconds_to_residual_1e-3")]
    pub seconds_to_1e3: Option<f64>,
    /// Sweeps (progressive refinement: shots / n) until then.
    #[serde(rename = "sweeps_to_residual_1e-3")]
    pub sweeps_to_1e3: Option<f64>,
    /// Relative RMS difference of B from the reference solution (area-weighted luminance).
    pub difference_from_reference: Option<f64>,
    /// Relative energy imbalance (see [`EnergyReport::imbalance`]).
    pub energy_imbalance: Option<f64>,
    /// Iterations, residual, time, rays and history.
    pub stats: Option<SolveStats>,
}

/// One rendered view.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ViewReport {
    /// View name.
    pub name: String,
    /// Files written for it.
    pub images: Vec<String>,
    /// Seconds to render it (not counting the shared solve).
    pub seconds: f64,
    /// Rays cast for it.
    pub rays: u64,
    /// How the final gather read the indirect light: "gathered (N×N rays per pixel
    /// position)" or "interpolated from the vertices"; None for Gouraud and flat images.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub indirect: Option<String>,
    /// Final gather: the mean number of positions a pixel took (adaptive sampling, at most
    /// `spp²`); None for Gouraud and flat images.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub positions_per_pixel: Option<f64>,
}

/// The whole report.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Report {
    /// Program version.
    pub version: String,
    /// Scene name.
    pub scene: String,
    /// Input polygons after validation.
    pub patches: usize,
    /// Elements.
    pub elements: usize,
    /// Target element size (scene units).
    pub mesh_size: f64,
    /// Form-factor statistics.
    pub form_factors: Option<form_factor::Stats>,
    /// Solver statistics (iterations, residual, history).
    pub solver: Option<SolveStats>,
    /// Iterations done.
    pub iterations: usize,
    /// Final relative residual.
    pub residual: f64,
    /// Rays cast in all stages.
    pub rays_cast: u64,
    /// Energy balance.
    pub energy: Option<EnergyReport>,
    /// Seconds per stage.
    pub timings: Timings,
    /// Per object.
    pub objects: Vec<ObjectReport>,
    /// Images written.
    pub images: Vec<String>,
    /// Views rendered from this one solve, with their own cost.
    pub views: Vec<ViewReport>,
    /// Warnings.
    pub warnings: Vec<String>,
    /// `solve --solver all`: the solver whose solution the report holds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_solver: Option<String>,
    /// `solve --solver all`: every solver on this scene.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub comparison: Vec<ComparisonRow>,
    /// Adaptive mesh refinement, pass by pass (absent for a uniform mesh).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub refinement: Vec<crate::mesh::adaptive::PassStats>,
}
