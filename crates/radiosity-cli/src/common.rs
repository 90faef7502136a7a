//! Flags shared by the subcommands and their validation into library settings.

use std::fs::File;
use std::io::{BufWriter, Write};
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
    /// Most elements: a uniform mesh above this is refused [default: 200000; 8000000 with
    /// --transport hierarchical]; with
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
    /// Transport operator: rows (a row of form factors per element: n² time and memory,
    /// every solver), hierarchical (links between clusters, patches and elements:
    /// n log n; jacobi and the stochastic solvers), or auto (hierarchical from 256 input
    /// polygons or above 50000 elements when the solver and form-factor method allow it;
    /// said at start).
    #[arg(long, value_name = "KIND", default_value = "auto")]
    pub transport: String,
    /// Hierarchical: a link is accepted when (size of receiver + size of source) / distance
    /// is below this.
    #[arg(long, value_name = "X", default_value_t = radiosity::form_factor::hierarchical::DEFAULT_SEPARATION)]
    pub link_separation: f64,
    /// Hierarchical: partially visible links carrying less than this fraction of the
    /// scene's power are kept instead of refined (BF refinement); links above it that every
    /// visibility ray finds hidden cast up to 32 times as many rays, more the more power
    /// they carry, before they are dropped (0: every such link, the full 32 times).
    #[arg(long, value_name = "TOL", default_value_t = radiosity::form_factor::hierarchical::DEFAULT_TOLERANCE)]
    pub link_tolerance: f64,
    /// Hierarchical: rays per link that classify its visibility (partial links are refined).
    #[arg(long, value_name = "N", default_value_t = radiosity::form_factor::hierarchical::DEFAULT_VISIBILITY_RAYS)]
    pub link_rays: usize,
    /// Hierarchical: only surface nodes (one plane) receive links; by default clusters of
    /// several planes receive indirect light too, spread to their elements by normal.
    #[arg(long)]
    pub no_cluster_receivers: bool,
    /// Hierarchical: nodes (groups of elements) whose bounding-box diagonal is at most
    /// this are not split to refine a link; 0 refines down to the elements [default: twice
    /// the mesh size above 50 000 elements, else 0].
    #[arg(long, value_name = "S")]
    pub link_min_size: Option<f64>,
    /// Hierarchical: emitted light goes through the links too; by default a scene with
    /// few emitting elements sends it to every element through exact factors.
    #[arg(long)]
    pub emitters_in_links: bool,
    /// Hierarchical: rays per element that measure its closure (the share of its hemisphere
    /// that meets a surface) and its exposure (the share that gets past the minimum size);
    /// what its links bring is scaled to close its row, clusters are seen and lit from afar
    /// through their exposed faces, and rows far short of their closure are traced by rays.
    /// 0 turns all three off [default: 64 where links go down to the elements, 16 where
    /// they stop at a minimum size].
    #[arg(long, value_name = "N")]
    pub link_closure_rays: Option<usize>,
    /// Hierarchical: pairs of nodes up to this many times the minimum size that are not
    /// well separated but carry at most --link-tolerance of the scene's power are linked
    /// as they stand (BF refinement) instead of split down to the minimum size; 0 splits
    /// them all.
    #[arg(long, value_name = "X", default_value_t = radiosity::form_factor::hierarchical::DEFAULT_COARSE_SIZE)]
    pub link_coarse_size: f64,
    /// Memory the run may use (e.g. 8G, 512M): refused before any work when the prediction
    /// is above it. Form-factor rows: their own size. Hierarchical transport: the whole
    /// run's peak resident memory (what the process holds after loading and meshing, the
    /// links, and the rest of the run per element), and watched again while the links are
    /// refined [default: the memory available].
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
    /// Solver: direct, jacobi, chebyshev (Jacobi accelerated: about half the sweeps),
    /// gauss-seidel, shooting, progressive, stochastic-jacobi, stochastic-shooting, or
    /// (solve only) all.
    #[arg(long, value_name = "NAME", default_value = "chebyshev")]
    pub solver: String,
    /// Stop when the relative power residual is at most this.
    #[arg(long, value_name = "TOL", default_value_t = 1e-4)]
    pub tolerance: f64,
    /// Stop after this many iterations: sweeps over every element for jacobi, chebyshev, gauss-seidel and
    /// shooting, ray iterations for the stochastic solvers, and sweeps of n shots (n = the
    /// element count) for progressive, whose report counts single shots.
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub max_iterations: usize,
    /// Stop solving after this many seconds (at most 1e9, about 31 years).
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
    /// A uniform sky around the scene: its radiance as one value or R,G,B (every ray that
    /// leaves the geometry sees it); replaces the radiance of the scene file's [sky] (its
    /// [sky.sun] stays); 0 removes it.
    #[arg(long, value_name = "L", value_parser = parse_sky)]
    pub sky: Option<[f64; 3]>,
    /// An environment image around the scene instead of a uniform sky: equirectangular,
    /// linear radiance by direction, +Y up (.exr, .hdr; .png/.jpg as sRGB); replaces the
    /// scene file's [sky] radiance or environment (its [sky.sun] stays).
    #[arg(long, value_name = "FILE")]
    pub sky_image: Option<std::path::PathBuf>,
    /// Multiplies the --sky-image texels.
    #[arg(long, value_name = "K", default_value_t = 1.0)]
    pub sky_strength: f64,
    /// Turns the --sky-image about +Y, degrees (counter-clockwise seen from above).
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_hyphen_values = true)]
    pub sky_rotation: f64,
    /// A sun: the direction towards it and its irradiance on a surface facing it,
    /// X,Y,Z,E (E one value; replaces the scene file's [sky.sun], keeps its sky radiance;
    /// E = 0 removes it). Its disk is --sun-diameter wide.
    #[arg(long, value_name = "X,Y,Z,E", value_parser = parse_sun)]
    pub sun: Option<[f64; 4]>,
    /// Angular diameter of --sun's disk, degrees (0 to 20; 0 is a point).
    #[arg(long, value_name = "DEG", requires = "sun", default_value_t = radiosity::scene::toml_file::DEFAULT_SUN_DIAMETER_DEG)]
    pub sun_diameter: f64,
    #[command(flatten)]
    pub adaptive: AdaptiveFlags,
    /// Seed for every random choice (results do not depend on --threads).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads, 1 to 1024 [default: all cores].
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
        let time_budget = self.time_budget.map(time_budget).transpose()?;
        check_threads(self.threads)?;
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
        let transport: radiosity::transport::Kind = self.transport.parse()?;
        let links = form_factor::hierarchical::Options {
            separation: self.link_separation,
            tolerance: self.link_tolerance,
            visibility_rays: self.link_rays,
            cluster_receivers: !self.no_cluster_receivers,
            min_size: self.link_min_size,
            direct_columns: !self.emitters_in_links,
            closure_rays: self.link_closure_rays,
            coarse_size: self.link_coarse_size,
        };
        links.validate()?;
        let hierarchical = transport == radiosity::transport::Kind::Hierarchical;
        if hierarchical && method != form_factor::Method::PointSampled {
            bail!(
                "--transport hierarchical computes its element-to-element links point-sampled; --form-factors {} applies to --transport rows",
                method.name()
            );
        }
        if !self.all_solvers() {
            radiosity::pipeline::check_transport(solver, transport)?;
        }
        let mut form_factors = self.ff.options(method, self.seed, self.visibility_samples)?;
        if let Some(m) = &self.memory_limit {
            form_factors.memory_limit = Some(crate::viewfactors::parse_size(m)?);
        }
        Ok(Settings {
            mesh_size: self.mesh_size,
            form_factors,
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
            max_elements_hierarchical: self.max_elements.unwrap_or(radiosity::pipeline::DEFAULT_MAX_ELEMENTS_HIERARCHICAL),
            adaptive: self.adaptive.options(self.max_elements)?,
            transport,
            links,
        })
    }

    /// True for `--solver all` (every solver, for comparison).
    pub fn all_solvers(&self) -> bool {
        self.solver == "all"
    }

    /// Configures the global thread pool.
    pub fn init_threads(&self) -> Result<()> {
        init_threads(self.threads)
    }

    /// Loads and validates the scene, printing its warnings; a scene that emits no light
    /// is an error (render and solve would give black).
    pub fn load_scene(&self) -> Result<(Scene, f64)> {
        let t = Instant::now();
        let mut desc = scene::load(&self.scene)?;
        desc.two_sided |= self.two_sided;
        desc.strict = self.strict;
        if self.sky.is_some() && self.sky_image.is_some() {
            anyhow::bail!("--sky and --sky-image: give a uniform sky or an environment image, not both");
        }
        // The scene's portals stay with a sky the flags replace.
        let portals = desc.sky.as_ref().map_or(Vec::new(), |s| s.portals.clone());
        if let Some(l) = self.sky {
            let sun = desc.sky.as_ref().and_then(|s| s.sun);
            let radiance = radiosity::Rgb::from_array(l);
            desc.sky = (radiance.max_element() > 0.0 || sun.is_some()).then_some(scene::Sky { radiance, sun, environment: None, portals: portals.clone() });
        }
        if let Some(path) = &self.sky_image {
            if !(self.sky_strength.is_finite() && self.sky_strength >= 0.0) {
                anyhow::bail!("--sky-strength {} must be a finite number ≥ 0", self.sky_strength);
            }
            if !self.sky_rotation.is_finite() {
                anyhow::bail!("--sky-rotation {} must be a finite number of degrees", self.sky_rotation);
            }
            let bytes = scene::read_input(path).map_err(|e| anyhow::anyhow!("--sky-image {}: {e}", path.display()))?;
            let texture = scene::Texture::decode_environment(&path.display().to_string(), &bytes)
                .map_err(|e| anyhow::anyhow!("--sky-image {}: {e}", path.display()))?;
            let env = scene::Environment {
                texture: std::sync::Arc::new(texture),
                strength: self.sky_strength,
                rotation_deg: self.sky_rotation,
            };
            let sun = desc.sky.as_ref().and_then(|s| s.sun);
            desc.sky = Some(scene::Sky { radiance: radiosity::Rgb::ZERO, sun, environment: Some(env), portals: portals.clone() });
        } else if self.sky_strength != 1.0 || self.sky_rotation != 0.0 {
            anyhow::bail!("--sky-strength and --sky-rotation need --sky-image");
        }
        if let Some([x, y, z, e]) = self.sun {
            if !(0.0..=scene::MAX_SUN_DIAMETER_DEG).contains(&self.sun_diameter) {
                anyhow::bail!("--sun-diameter {} must be between 0 and {} degrees", self.sun_diameter, scene::MAX_SUN_DIAMETER_DEG);
            }
            let radiance = desc.sky.as_ref().map_or(radiosity::Rgb::ZERO, |s| s.radiance);
            let environment = desc.sky.as_ref().and_then(|s| s.environment.clone());
            let sun = (e > 0.0).then(|| scene::Sun {
                direction: glam::DVec3::new(x, y, z),
                irradiance: radiosity::Rgb::splat(e),
                angular_diameter_deg: self.sun_diameter,
            });
            desc.sky = (radiance.max_element() > 0.0 || sun.is_some() || environment.is_some())
                .then_some(scene::Sky { radiance, sun, environment, portals: portals.clone() });
        }
        let scene = Scene::from_desc(desc)?;
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
        scene.check_emits()?;
        Ok((scene, t.elapsed().as_secs_f64()))
    }
}

/// `--sky L` or `--sky R,G,B`: finite, non-negative radiance.
fn parse_sky(s: &str) -> std::result::Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let vals: Vec<f64> = parts
        .iter()
        .map(|p| p.parse::<f64>().map_err(|_| format!("'{p}' is not a number")))
        .collect::<std::result::Result<_, _>>()?;
    let v = match vals.as_slice() {
        [g] => [*g; 3],
        [r, g, b] => [*r, *g, *b],
        _ => return Err(format!("expected one radiance or three (R,G,B), got {}", vals.len())),
    };
    if v.iter().any(|c| !c.is_finite() || *c < 0.0) {
        return Err(format!("sky radiance {v:?} must be finite and non-negative"));
    }
    Ok(v)
}

/// `--sun X,Y,Z,E`: a finite, non-zero direction and a finite, non-negative irradiance.
fn parse_sun(s: &str) -> std::result::Result<[f64; 4], String> {
    let vals: Vec<f64> = s
        .split(',')
        .map(str::trim)
        .map(|p| p.parse::<f64>().map_err(|_| format!("'{p}' is not a number")))
        .collect::<std::result::Result<_, _>>()?;
    let [x, y, z, e] = vals.as_slice() else {
        return Err(format!("expected X,Y,Z,E (direction towards the sun, irradiance), got {} numbers", vals.len()));
    };
    if ![x, y, z].iter().all(|c| c.is_finite()) || (x * x + y * y + z * z) == 0.0 {
        return Err(format!("sun direction [{x}, {y}, {z}] must be a finite, non-zero vector"));
    }
    if !(e.is_finite() && *e >= 0.0) {
        return Err(format!("sun irradiance {e} must be finite and non-negative"));
    }
    Ok([*x, *y, *z, *e])
}

/// The largest `--time-budget`, in seconds (about 31 years): far beyond any run, far below
/// what a `Duration` holds.
pub const MAX_TIME_BUDGET_S: f64 = 1e9;

/// The most worker threads `--threads` accepts.
pub const MAX_THREADS: usize = 1024;

/// A validated `--time-budget`: positive, finite, at most [`MAX_TIME_BUDGET_S`].
pub fn time_budget(t: f64) -> Result<Duration> {
    if !(t.is_finite() && t > 0.0) {
        bail!("--time-budget must be a positive number of seconds, got {t}");
    }
    if t > MAX_TIME_BUDGET_S {
        bail!("--time-budget must be at most {MAX_TIME_BUDGET_S:e} seconds (about 31 years), got {t:e}");
    }
    Ok(Duration::from_secs_f64(t))
}

/// Validates `--threads` (1 to [`MAX_THREADS`]) before any work starts.
pub fn check_threads(threads: Option<usize>) -> Result<()> {
    match threads {
        Some(n) if n == 0 || n > MAX_THREADS => {
            bail!("--threads must be between 1 and {MAX_THREADS}, got {n}")
        }
        _ => Ok(()),
    }
}

/// Validates `--threads` and configures the global thread pool.
pub fn init_threads(threads: Option<usize>) -> Result<()> {
    check_threads(threads)?;
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .with_context(|| format!("--threads {n}: cannot start the worker threads"))?;
    }
    Ok(())
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

/// Writes `bytes` to `path` atomically (temporary file in the same folder, flushed to disk,
/// then renamed over the target), creating the folder if needed. See [`write_atomic_with`].
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |mut w| {
        w.write_all(bytes)?;
        w.flush()?;
        Ok(())
    })
}

/// Writes `path` atomically through `f`, which gets a buffered temporary file beside the
/// target and must flush it. The temporary file is synced to disk (so that a full disk is
/// an error here, not a truncated file later) and renamed over the target; on every failure
/// (write, sync, rename) it is removed. A target that exists and is not a regular file (a
/// directory, a device such as /dev/null, a FIFO, a socket) is refused, never replaced.
pub fn write_atomic_with(path: &Path, f: impl FnOnce(BufWriter<File>) -> Result<()>) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().with_context(|| format!("{}: not a file name", path.display()))?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create folder {}", dir.display()))?;
    // Checked again here: the target may have appeared since the check before the work.
    if let Some(why) = not_replaceable(path) {
        bail!("cannot write {}: {why}", path.display());
    }
    let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    let result = (|| -> Result<()> {
        let file = File::create(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
        let handle = file.try_clone().with_context(|| format!("cannot write {}", tmp.display()))?;
        f(BufWriter::with_capacity(1 << 20, file)).with_context(|| format!("cannot write {}", path.display()))?;
        handle.sync_all().with_context(|| format!("cannot write {}", path.display()))?;
        std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Why an existing `path` must not be replaced by a rename (None: absent or a regular file).
fn not_replaceable(path: &Path) -> Option<String> {
    let meta = std::fs::metadata(path).ok()?;
    let ft = meta.file_type();
    if ft.is_file() {
        return None;
    }
    if ft.is_dir() {
        return Some("it is a directory".into());
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let kind = if ft.is_char_device() {
            "a character device"
        } else if ft.is_block_device() {
            "a block device"
        } else if ft.is_fifo() {
            "a FIFO (named pipe)"
        } else if ft.is_socket() {
            "a socket"
        } else {
            "not a regular file"
        };
        return Some(format!("it is {kind}, not a regular file; refusing to replace it (write to a regular file)"));
    }
    #[allow(unreachable_code)]
    Some("it is not a regular file; refusing to replace it (write to a regular file)".into())
}

/// The output files of a run, checked together before any work starts.
#[derive(Default)]
pub struct Outputs {
    files: Vec<(String, PathBuf)>,
    /// Files whose format is fixed: index into `files`, extension, format name.
    formats: Vec<(usize, &'static str, &'static str)>,
}

impl Outputs {
    /// Adds the file `path` named by `flag` (e.g. "-o", "--report").
    pub fn add(&mut self, flag: &str, path: &Path) {
        self.files.push((flag.to_string(), path.to_path_buf()));
    }

    /// Adds a file written in one format, `format` (e.g. "PNG"), whose name must end in
    /// `.ext` (any case): an image named `.jpg` holding PNG data is refused, not written.
    pub fn add_format(&mut self, flag: &str, path: &Path, ext: &'static str, format: &'static str) {
        self.formats.push((self.files.len(), ext, format));
        self.add(flag, path);
    }

    /// Checks every output: a file name, distinct from the others, not an existing
    /// directory or special file, and in a folder that exists (or can be created) and is
    /// writable. Nothing is created but a probe file, removed at once.
    pub fn check(&self) -> Result<()> {
        let mut seen: Vec<(PathBuf, &str, &Path)> = Vec::new();
        for (k, (flag, path)) in self.files.iter().enumerate() {
            check_output(flag, path)?;
            let key = normalized(path);
            if let Some((_, other, p)) = seen.iter().find(|(k, _, _)| *k == key) {
                if other == flag {
                    bail!("{flag}: two outputs are the same file {} (and {}): outputs must be distinct", path.display(), p.display());
                }
                bail!("{other} {} and {flag} {} are the same file: outputs must be distinct", p.display(), path.display());
            }
            if let Some(&(_, ext, format)) = self.formats.iter().find(|f| f.0 == k) {
                if !path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case(ext)) {
                    bail!("{flag} {}: this writes {format}; name the file .{ext}", path.display());
                }
            }
            seen.push((key, flag, path));
        }
        Ok(())
    }
}

/// The pre-check of one output (see [`Outputs::check`]).
fn check_output(flag: &str, path: &Path) -> Result<()> {
    if path.file_name().is_none() {
        bail!("{flag} {}: not a file name", path.display());
    }
    if let Some(why) = not_replaceable(path) {
        bail!("{flag} {}: {why}", path.display());
    }
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    // The nearest folder that exists: the file's own, or the one its folders will be made in.
    let mut existing = dir;
    while !existing.exists() {
        match existing.parent() {
            Some(p) if !p.as_os_str().is_empty() => existing = p,
            _ => {
                existing = Path::new(".");
                break;
            }
        }
    }
    if !existing.is_dir() {
        bail!("{flag} {}: {} is not a folder", path.display(), existing.display());
    }
    let probe = existing.join(format!(".radiosity-probe-{}", std::process::id()));
    match File::options().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        // A folder that exists but where the system makes no new files (/proc) reports "No
        // such file": say so instead of only quoting it.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "{flag} {}: cannot write in folder {}: it exists but takes no new files ({e})",
            path.display(),
            existing.display()
        ),
        Err(e) => bail!("{flag} {}: cannot write in folder {}: {e}", path.display(), existing.display()),
    }
    Ok(())
}

/// `path` made absolute with its existing folders resolved (symbolic links, `..`), so that
/// two spellings of one file compare equal.
fn normalized(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    let name = path.file_name().map(PathBuf::from).unwrap_or_default();
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    match std::fs::canonicalize(dir) {
        Ok(d) => d.join(name),
        Err(_) => {
            let abs = std::env::current_dir().map(|c| c.join(path)).unwrap_or_else(|_| path.to_path_buf());
            let mut out = PathBuf::new();
            for c in abs.components() {
                match c {
                    std::path::Component::CurDir => {}
                    std::path::Component::ParentDir => {
                        out.pop();
                    }
                    c => out.push(c),
                }
            }
            out
        }
    }
}

/// One line per term of the energy balance, for the summary on stderr.
pub fn energy_summary(e: &radiosity::report::EnergyReport) -> String {
    let lum = |c: [f64; 3]| radiosity::luminance(glam::DVec3::from_array(c));
    let emitted = lum(e.emitted).max(f64::MIN_POSITIVE);
    // A share that rounds to zero prints as 0.00, not −0.00 (a solve whose last iterate
    // overshot by a hair leaves a tiny negative unshot share).
    let pct = |c: [f64; 3]| {
        let v = 100.0 * lum(c) / emitted;
        if v.abs() < 0.005 {
            0.0
        } else {
            v
        }
    };
    let line = format!(
        "energy: emitted {:.4e} = absorbed {:.2} % + escaped {:.2} % + back faces {:.2} % + unshot {:.2} % (imbalance {:.1e})",
        lum(e.emitted),
        pct(e.absorbed),
        pct(e.escaped),
        pct(e.back_faces),
        pct(e.unshot),
        e.imbalance
    );
    let lights = match e.lights_power {
        Some(p) => format!(" (the point and spot lights send {:.4e})", lum(p)),
        None => String::new(),
    };
    match e.external_incident {
        Some(s) => format!(
            "{line}\n        sky and lights: {:.4e} reaches the surfaces directly{lights}; its first reflection is part of the emitted",
            lum(s)
        ),
        None => line,
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("radiosity-common-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn leftovers(d: &Path) -> Vec<String> {
        std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp"))
            .collect()
    }

    #[test]
    fn atomic_write_removes_its_temporary_file_when_the_rename_fails() {
        let d = dir("rename");
        // The target is an existing directory: refused before any temporary file.
        let target = d.join("out.png");
        std::fs::create_dir_all(target.join("inside")).unwrap();
        let err = write_atomic(&target, b"data").unwrap_err().to_string();
        assert!(err.contains("out.png") && err.contains("directory"), "{err}");
        assert!(leftovers(&d).is_empty(), "left behind: {:?}", leftovers(&d));
        // The target becomes a non-empty directory while the file is written (after every
        // check): the rename fails, and the temporary file is removed.
        let late = d.join("late.png");
        let err = write_atomic_with(&late, |mut w| {
            w.write_all(b"data")?;
            w.flush()?;
            std::fs::create_dir_all(late.join("inside"))?;
            Ok(())
        })
        .unwrap_err();
        assert!(format!("{err:#}").contains("late.png"), "{err:#}");
        assert!(late.join("inside").is_dir());
        assert!(leftovers(&d).is_empty(), "left behind: {:?}", leftovers(&d));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn atomic_write_removes_its_temporary_file_when_writing_fails() {
        let d = dir("write");
        let target = d.join("r.json");
        let err = write_atomic_with(&target, |_| bail!("No space left on device (os error 28)")).unwrap_err();
        assert!(format!("{err:#}").contains("No space left"), "{err:#}");
        assert!(!target.exists());
        assert!(leftovers(&d).is_empty(), "left behind: {:?}", leftovers(&d));
        // And a good write leaves only the file.
        write_atomic(&target, b"{}").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"{}");
        assert!(leftovers(&d).is_empty());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn atomic_write_to_a_special_file_fails_and_keeps_it() {
        // A FIFO of our own stands in for a device such as /dev/full (never touch real
        // device nodes from a test that runs as root): the write path refuses it and keeps it.
        let d = dir("special");
        let fifo = d.join("fifo");
        let _ = std::fs::remove_file(&fifo);
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
        let err = write_atomic(&fifo, b"x").unwrap_err().to_string();
        assert!(err.contains("FIFO"), "{err}");
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
        let mut o = Outputs::default();
        o.add("-o", &fifo);
        let err = o.check().unwrap_err().to_string();
        assert!(err.contains("-o") && err.contains("not a regular file"), "{err}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn outputs_must_be_distinct_writable_regular_files() {
        let d = dir("outputs");
        let mut o = Outputs::default();
        o.add("-o", &d.join("x.png"));
        o.add("--exr", &d.join("sub/../x.png"));
        std::fs::create_dir_all(d.join("sub")).unwrap();
        let err = o.check().unwrap_err().to_string();
        assert!(err.contains("-o") && err.contains("--exr") && err.contains("distinct"), "{err}");
        let mut o = Outputs::default();
        o.add("--report", &d);
        let err = o.check().unwrap_err().to_string();
        assert!(err.contains("--report") && err.contains("is a directory"), "{err}");
        std::fs::write(d.join("file"), b"").unwrap();
        let mut o = Outputs::default();
        o.add("-o", &d.join("file/x.png"));
        let err = o.check().unwrap_err().to_string();
        assert!(err.contains("is not a folder"), "{err}");
        // Folders that do not exist yet are fine (they are created), and nothing is left.
        let mut o = Outputs::default();
        o.add("-o", &d.join("new/deeper/x.png"));
        o.check().unwrap();
        assert!(!d.join("new").exists());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn time_budget_and_threads_are_bounded() {
        assert!(time_budget(1e300).unwrap_err().to_string().contains("at most 1e9"));
        assert!(time_budget(f64::INFINITY).is_err() && time_budget(0.0).is_err() && time_budget(-1.0).is_err());
        assert_eq!(time_budget(2.5).unwrap(), Duration::from_millis(2500));
        assert!(check_threads(Some(5000)).unwrap_err().to_string().contains("between 1 and 1024"));
        assert!(check_threads(Some(0)).is_err());
        assert!(check_threads(Some(1024)).is_ok() && check_threads(None).is_ok());
    }
}
