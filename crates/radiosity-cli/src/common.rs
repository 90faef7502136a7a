//! Flags shared by the subcommands and their validation into library settings.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use radiosity::pipeline::Settings;
use radiosity::scene::Scene;
use radiosity::solve::{Solver, StopReason};
use radiosity::{form_factor, scene};

/// Scene, meshing, form factors and solver.
#[derive(Args, Debug, Clone)]
pub struct SolveFlags {
    /// Scene: a file (.obj, .gltf, .glb, .toml) or a built-in name (cornell, furnace).
    #[arg(default_value = "cornell")]
    pub scene: String,
    /// Target element size in scene units [default: scene diagonal / 36].
    #[arg(long, value_name = "S")]
    pub mesh_size: Option<f64>,
    /// Most elements: a uniform mesh above this is refused [default: 200000]; with
    /// --adaptive, also the limit of refinement [default: twice the uniform mesh's count].
    #[arg(long, value_name = "N")]
    pub max_elements: Option<u64>,
    /// Form-factor method.
    #[arg(long = "form-factors", value_name = "METHOD", default_value = "point-sampled")]
    pub form_factors: String,
    /// Visibility rays per receiver point (n × n).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub visibility_samples: usize,
    #[command(flatten)]
    pub ff: FormFactorTuning,
    /// Solver: direct, jacobi, gauss-seidel, shooting, progressive, stochastic-jacobi,
    /// stochastic-shooting, or (solve only) all.
    #[arg(long, value_name = "NAME", default_value = "jacobi")]
    pub solver: String,
    /// Stop when the relative power residual is at most this.
    #[arg(long, value_name = "TOL", default_value_t = 1e-4)]
    pub tolerance: f64,
    /// Stop after this many iterations.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub max_iterations: usize,
    /// Stop solving after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub time_budget: Option<f64>,
    /// Stochastic solvers: rays per iteration for the full emitted power [default: 500 per
    /// element, at least 200 000].
    #[arg(long, value_name = "N")]
    pub rays: Option<u64>,
    /// Treat every surface as two-sided.
    #[arg(long)]
    pub two_sided: bool,
    /// Refuse a reflectance ≥ 1 (e.g. glTF's default white) instead of lowering it to 0.95.
    #[arg(long)]
    pub strict: bool,
    #[command(flatten)]
    pub adaptive: AdaptiveFlags,
    /// Seed for every random choice (results do not depend on --threads).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Write the JSON report here.
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// No progress bars or messages (errors and warnings still print).
    #[arg(long, short)]
    pub quiet: bool,
}

impl SolveFlags {
    /// Validates the flags into settings.
    pub fn settings(&self) -> Result<Settings> {
        if let Some(s) = self.mesh_size {
            if !(s.is_finite() && s > 0.0) {
                bail!("--mesh-size must be a positive number, got {s}");
            }
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            bail!("--tolerance must be a non-negative number, got {}", self.tolerance);
        }
        if self.visibility_samples == 0 || self.visibility_samples > 16 {
            bail!("--visibility-samples must be between 1 and 16");
        }
        let time_budget = match self.time_budget {
            Some(t) if t.is_finite() && t > 0.0 => Some(Duration::from_secs_f64(t)),
            Some(t) => bail!("--time-budget must be a positive number of seconds, got {t}"),
            None => None,
        };
        let method: form_factor::Method = self.form_factors.parse()?;
        // `all` is a mode of `solve`, not a solver: the settings then carry a placeholder.
        let solver: Solver = if self.all_solvers() {
            Solver::Jacobi
        } else {
            self.solver.parse().map_err(|e| anyhow::anyhow!("{e}, or all (solve only)"))?
        };
        if self.rays == Some(0) {
            bail!("--rays must be at least 1");
        }
        Ok(Settings {
            mesh_size: self.mesh_size,
            form_factors: self.ff.options(method, self.seed, self.visibility_samples)?,
            solver,
            solve: radiosity::solve::Options {
                tolerance: self.tolerance,
                max_iterations: self.max_iterations,
                time_budget,
                seed: self.seed,
                rays: self.rays,
                ..Default::default()
            },
            max_elements: self.max_elements.unwrap_or(radiosity::pipeline::DEFAULT_MAX_ELEMENTS),
            adaptive: self.adaptive.options(self.max_elements)?,
        })
    }

    /// True for `--solver all` (every solver, for comparison).
    pub fn all_solvers(&self) -> bool {
        self.solver == "all"
    }

    /// Configures the global thread pool.
    pub fn init_threads(&self) -> Result<()> {
        if let Some(n) = self.threads {
            if n == 0 {
                bail!("--threads must be at least 1");
            }
            rayon::ThreadPoolBuilder::new().num_threads(n).build_global().context("setting up threads")?;
        }
        Ok(())
    }

    /// Loads and validates the scene, printing its warnings; a scene that emits no light
    /// is an error (render and solve would give black).
    pub fn load_scene(&self) -> Result<(Scene, f64)> {
        let t = Instant::now();
        let mut desc = scene::load(&self.scene)?;
        desc.two_sided |= self.two_sided;
        desc.strict = self.strict;
        let scene = Scene::from_desc(desc)?;
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
        scene.check_emits()?;
        Ok((scene, t.elapsed().as_secs_f64()))
    }
}

/// Accuracy settings of the form-factor methods (shared by render, solve, viewfactors).
#[derive(Args, Debug, Clone)]
pub struct FormFactorTuning {
    /// Hemicube: pixels along the top face (even; side faces are N × N/2).
    #[arg(long, value_name = "N", default_value_t = form_factor::hemicube::DEFAULT_RESOLUTION)]
    pub hemicube_resolution: usize,
    /// Monte Carlo: rays per sender element.
    #[arg(long, value_name = "N", default_value_t = form_factor::monte_carlo::DEFAULT_RAYS)]
    pub mc_rays: usize,
    /// Adaptive: relative tolerance of each form factor.
    #[arg(long, value_name = "TOL", default_value_t = form_factor::adaptive::DEFAULT_TOLERANCE)]
    pub ff_tolerance: f64,
}

impl FormFactorTuning {
    /// Validated form-factor options.
    pub fn options(&self, method: form_factor::Method, seed: u64, visibility_samples: usize) -> Result<form_factor::Options> {
        let o = form_factor::Options {
            method,
            seed,
            visibility_samples,
            hemicube_resolution: self.hemicube_resolution,
            mc_rays: self.mc_rays,
            adaptive_tolerance: self.ff_tolerance,
            ..Default::default()
        };
        o.validate()?;
        Ok(o)
    }
}

/// Adaptive meshing (`radiosity::mesh::adaptive`).
#[derive(Args, Debug, Clone)]
pub struct AdaptiveFlags {
    /// Refine the mesh where light changes fast (shadow boundaries, contact edges); then
    /// --mesh-size is the size before refinement.
    #[arg(long)]
    pub adaptive: bool,
    /// Refine an element whose estimated variation exceeds this fraction of the mean exitance.
    #[arg(long, value_name = "T", requires = "adaptive")]
    pub refine_threshold: Option<f64>,
    /// Most levels of 1→4 splits below a uniform element.
    #[arg(long, value_name = "N", requires = "adaptive")]
    pub max_depth: Option<u32>,
    /// Refinement passes after a solve, on the indirect light (each recomputes form factors).
    #[arg(long, value_name = "N", requires = "adaptive")]
    pub refine_passes: Option<usize>,
    /// Criteria before solving: direct, contact, both or none.
    #[arg(long, value_name = "WHICH", requires = "adaptive")]
    pub refine_a_priori: Option<String>,
}

impl AdaptiveFlags {
    /// The adaptive options, if --adaptive.
    /// `max_elements` is the shared --max-elements flag (the refinement limit here).
    pub fn options(&self, max_elements: Option<u64>) -> Result<Option<radiosity::mesh::adaptive::Options>> {
        if !self.adaptive {
            return Ok(None);
        }
        let mut o = radiosity::mesh::adaptive::Options::default();
        if let Some(t) = self.refine_threshold {
            if !(t.is_finite() && t > 0.0) {
                bail!("--refine-threshold must be a positive number, got {t}");
            }
            o.threshold = t;
        }
        o.max_elements = max_elements.map(|n| n as usize);
        if let Some(d) = self.max_depth {
            if d > 12 {
                bail!("--max-depth must be at most 12");
            }
            o.max_depth = d;
        }
        if let Some(p) = self.refine_passes {
            o.passes = p;
        }
        if let Some(w) = &self.refine_a_priori {
            (o.direct, o.contact) = match w.as_str() {
                "both" => (true, true),
                "direct" => (true, false),
                "contact" => (false, true),
                "none" => (false, false),
                _ => bail!("--refine-a-priori must be direct, contact, both or none, got '{w}'"),
            };
        }
        Ok(Some(o))
    }
}

/// Writes `bytes` to `path` atomically (temporary file in the same folder, then rename),
/// creating the folder if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().with_context(|| format!("{}: not a file name", path.display()))?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create folder {}", dir.display()))?;
    let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    std::fs::write(&tmp, bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// One line per term of the energy balance, for the summary on stderr.
pub fn energy_summary(e: &radiosity::report::EnergyReport) -> String {
    let lum = |c: [f64; 3]| radiosity::luminance(glam::DVec3::from_array(c));
    let emitted = lum(e.emitted).max(f64::MIN_POSITIVE);
    let pct = |c: [f64; 3]| 100.0 * lum(c) / emitted;
    format!(
        "energy: emitted {:.4e} = absorbed {:.2} % + escaped {:.2} % + unshot {:.2} % (imbalance {:.1e})",
        lum(e.emitted),
        pct(e.absorbed),
        pct(e.escaped),
        pct(e.unshot),
        e.imbalance
    )
}

/// The exit code for a run that stopped for `reason`: 130 after an interrupt (outputs were
/// still written), else 0.
pub fn exit_code(reason: StopReason) -> ExitCode {
    if reason == StopReason::Interrupted || crate::progress::stopped() {
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    }
}
