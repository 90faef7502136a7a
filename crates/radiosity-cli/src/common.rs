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
    /// Target element size in scene units [default: scene diagonal / 32].
    #[arg(long, value_name = "S")]
    pub mesh_size: Option<f64>,
    /// Refuse meshes with more elements than this.
    #[arg(long, value_name = "N", default_value_t = radiosity::pipeline::DEFAULT_MAX_ELEMENTS)]
    pub max_elements: u64,
    /// Form-factor method.
    #[arg(long = "form-factors", value_name = "METHOD", default_value = "point-sampled")]
    pub form_factors: String,
    /// Visibility rays per receiver point (n × n).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub visibility_samples: usize,
    #[command(flatten)]
    pub ff: FormFactorTuning,
    /// Solver.
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
    /// Treat every surface as two-sided.
    #[arg(long)]
    pub two_sided: bool,
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
        let solver: Solver = self.solver.parse()?;
        Ok(Settings {
            mesh_size: self.mesh_size,
            form_factors: self.ff.options(method, self.seed, self.visibility_samples)?,
            solver,
            solve: radiosity::solve::Options { tolerance: self.tolerance, max_iterations: self.max_iterations, time_budget },
            max_elements: self.max_elements,
        })
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

    /// Loads and validates the scene, printing its warnings.
    pub fn load_scene(&self) -> Result<(Scene, f64)> {
        let t = Instant::now();
        let mut desc = scene::load(&self.scene)?;
        desc.two_sided |= self.two_sided;
        let scene = Scene::from_desc(desc)?;
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
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

/// The exit code for a run that stopped for `reason`: 130 after an interrupt (outputs were
/// still written), else 0.
pub fn exit_code(reason: StopReason) -> ExitCode {
    if reason == StopReason::Interrupted || crate::progress::stopped() {
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    }
}
