//! `radiosity render`: solve, then draw the scene from one camera or a list of views;
//! `--frames DIR` also draws the scene after every solver iteration.

use std::cell::OnceCell;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use glam::DVec3;
use radiosity::mesh::Mesh;
use radiosity::output;
use radiosity::pipeline::{render_radiosity, solve_scene, solve_scene_observed};
use radiosity::render::gather;
use radiosity::render::gouraud::{self, ElementTracer, Shading};
use radiosity::render::Image;
use radiosity::report::ViewReport;
use radiosity::scene::{Camera, Scene};
use radiosity::solve::IterationState;
use radiosity::NoProgress;

use crate::common::{energy_summary, exit_code, write_atomic, SolveFlags};
use crate::progress::CliProgress;

/// Flags of `radiosity render`.
#[derive(Args, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub solve: SolveFlags,
    /// PNG output [default: <scene name>.png in the current directory].
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Also write linear radiance (L = B/π) as OpenEXR.
    #[arg(long, value_name = "FILE")]
    pub exr: Option<PathBuf>,
    /// Camera JSON (position, look_at, up, vfov_deg), as ../shared/scenes/cornell-box/camera.json.
    #[arg(long, value_name = "FILE", conflicts_with = "views")]
    pub camera: Option<PathBuf>,
    /// Several views rendered from one solve: a JSON array of cameras (each may have a
    /// "name"). Outputs are named <output stem>_<view name>.png (and .exr).
    #[arg(long, value_name = "FILE")]
    pub views: Option<PathBuf>,
    /// Camera position x,y,z (overrides the scene's camera).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point the camera looks at, x,y,z.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub look_at: Option<DVec3>,
    /// Camera up direction, x,y,z.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<DVec3>,
    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEGREES")]
    pub fov: Option<f64>,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: usize,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    pub height: usize,
    /// Samples per pixel along each axis (box filter) [default: 6 for gather, 3 for
    /// gouraud and flat].
    #[arg(long, value_name = "N")]
    pub spp: Option<usize>,
    /// Image reconstruction: gather (direct light per pixel, indirect from the solution;
    /// matches a path tracer), gouraud (radiosity interpolated from vertices; instant
    /// preview) or flat (one value per element).
    #[arg(long = "render", value_name = "MODE", default_value = "gather")]
    pub mode: String,
    /// Final gather: shadow rays per pixel sample and emitter, as N × N.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub shadow_rays: usize,
    /// PNG exposure: radiance is multiplied by this before sRGB encoding [default: automatic].
    #[arg(long, value_name = "SCALE")]
    pub exposure: Option<f64>,
    /// Also write an image after every solver iteration into this folder (frame-0001.png …
    /// and frames.json): light flowing into the scene bounce by bounce (progressive
    /// refinement: after 1, 2, 4 … shots, then every n shots). Frames are Gouraud previews
    /// of the first view, all at the final image's exposure, so the sequence brightens.
    #[arg(long, value_name = "DIR")]
    pub frames: Option<PathBuf>,
}

/// One frame of `--frames`, kept in memory (f32) until the final exposure is known.
struct Frame {
    iteration: usize,
    residual: f64,
    seconds: f64,
    rays: u64,
    pixels: Vec<[f32; 3]>,
}

fn parse_vec3(s: &str) -> Result<DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|_| format!("'{t}' is not a number")))
        .collect::<Result<_, _>>()?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("expected three finite numbers x,y,z, got '{s}'"));
    }
    Ok(DVec3::new(v[0], v[1], v[2]))
}

pub fn run(a: RenderArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let settings = a.solve.settings()?;
    a.solve.init_threads()?;
    if a.solve.all_solvers() {
        bail!("--solver all compares solvers: use it with `radiosity solve` (and --plot); render one solver");
    }
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        bail!("--width and --height must be between 1 and 16384");
    }
    let spp = a.spp.unwrap_or(if a.mode == "gather" { 6 } else { 3 });
    if spp == 0 || spp > 64 {
        bail!("--spp must be between 1 and 64");
    }
    let shading = match a.mode.as_str() {
        "gouraud" | "gather" => Shading::Gouraud,
        "flat" => Shading::Flat,
        s => bail!("unknown --render '{s}' (known: gather, gouraud, flat)"),
    };
    let gather = a.mode == "gather";
    if a.shadow_rays == 0 || a.shadow_rays > 16 {
        bail!("--shadow-rays must be between 1 and 16");
    }
    if let Some(e) = a.exposure {
        if !(e.is_finite() && e > 0.0) {
            bail!("--exposure must be a positive number");
        }
    }
    let file_camera = match &a.camera {
        Some(p) => Some(Camera::load_json(p)?),
        None => None,
    };
    let view_list = match &a.views {
        Some(p) => Some(Camera::load_views(p)?),
        None => None,
    };
    let (scene, load_s) = a.solve.load_scene()?;
    let out_png = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.png", scene.name)));
    // The views: one (file, flags, the scene's own camera, or a framing default) or a list.
    let views: Vec<(String, Camera, PathBuf, Option<PathBuf>)> = match view_list {
        None => {
            let mut cam = file_camera.or(scene.camera).unwrap_or_else(|| {
                let (lo, hi) = scene.bounds();
                Camera::framing(lo, hi)
            });
            if let Some(v) = a.eye {
                cam.position = v;
            }
            if let Some(v) = a.look_at {
                cam.look_at = v;
            }
            if let Some(v) = a.up {
                cam.up = v;
            }
            if let Some(f) = a.fov {
                cam.vfov_deg = f;
            }
            let from = if a.eye.is_some() || a.look_at.is_some() || a.up.is_some() || a.fov.is_some() {
                "--eye/--look-at/--up/--fov"
            } else {
                "camera"
            };
            cam.validate().map_err(|m| anyhow::anyhow!("{from}: {m}"))?;
            vec![("main".to_string(), cam, out_png.clone(), a.exr.clone())]
        }
        Some(list) => list
            .into_iter()
            .map(|(name, cam)| {
                let png = suffixed(&out_png, &name);
                let exr = a.exr.as_ref().map(|e| suffixed(e, &name));
                (name, cam, png, exr)
            })
            .collect(),
    };

    let progress = CliProgress::new(a.solve.quiet);
    let preview = gouraud::Options { width: a.width, height: a.height, spp_axis: spp.min(3), shading };
    let two_sided_of = |scene: &Scene| -> Vec<bool> { scene.polygons.iter().map(|p| p.two_sided).collect() };
    let tracer_cell: OnceCell<ElementTracer> = OnceCell::new();
    let mut frames: Vec<Frame> = Vec::new();
    let frame_cam = views[0].1;
    let solved = if a.frames.is_some() {
        let mut observer = |scene: &Scene, mesh: &Mesh, st: &IterationState| {
            let tracer = tracer_cell.get_or_init(|| ElementTracer::new(mesh, &two_sided_of(scene)));
            let img = render_radiosity(scene, mesh, tracer, st.radiosity, &frame_cam, &preview, &NoProgress);
            let pixels = img.pixels.iter().map(|p| p.as_vec3().to_array()).collect();
            frames.push(Frame { iteration: st.iteration, residual: st.residual, seconds: st.seconds, rays: st.rays, pixels });
        };
        solve_scene_observed(scene, &settings, &progress, Some(&mut observer))?
    } else {
        solve_scene(scene, &settings, &progress)?
    };
    let stats = &solved.solution.stats;
    if !a.solve.quiet {
        let ff = match &solved.ff_stats {
            Some(f) => format!("{} form factors ({} rays)", f.nonzeros, f.rays),
            None => "no form factors".into(),
        };
        let rays = if stats.rays > 0 { format!(", {} solver rays", stats.rays) } else { String::new() };
        eprintln!(
            "{} elements, {ff}, {} {} iterations, residual {:.2e} ({:?}){rays}",
            solved.mesh.len(),
            stats.solver,
            stats.iterations,
            stats.residual,
            stats.stop
        );
        eprintln!("{}", energy_summary(&solved.energy()));
    }

    let t = Instant::now();
    let tracer =
        tracer_cell.into_inner().unwrap_or_else(|| ElementTracer::new(&solved.mesh, &two_sided_of(&solved.scene)));
    let indirect = if gather { Some(solved.indirect_irradiance().1) } else { None };
    let mut report = solved.report();
    report.timings.load = load_s;
    // Images are drawn even after an interrupt: the solution so far is what we have.
    let quiet = CliProgress::new(a.solve.quiet);
    let mut first_exposure = None;
    for (name, cam, png_path, exr_path) in &views {
        let tv = Instant::now();
        let (img, rays) = match &indirect {
            Some(hv) => {
                let gopts = gather::Options {
                    width: a.width,
                    height: a.height,
                    spp_axis: spp,
                    shadow_axis: a.shadow_rays,
                    seed: a.solve.seed,
                };
                solved.render_gather(cam, &gopts, &tracer, hv, &NeverStop(&quiet))
            }
            None => {
                let opts = gouraud::Options { width: a.width, height: a.height, spp_axis: spp, shading };
                let img = solved.render(cam, &opts, &tracer, &NeverStop(&quiet));
                let rays = (a.width * a.height * spp * spp) as u64;
                (img, rays)
            }
        };
        let mut files = vec![png_path.display().to_string()];
        let exposure = a.exposure.unwrap_or_else(|| output::auto_exposure(&img));
        first_exposure.get_or_insert(exposure);
        write_atomic(png_path, &output::png::encode(&img, Some(exposure))?)?;
        if let Some(p) = exr_path {
            write_atomic(p, &output::exr::encode(&img)?)?;
            files.push(p.display().to_string());
        }
        report.rays_cast += rays;
        report.images.extend(files.iter().cloned());
        report.views.push(ViewReport { name: name.clone(), images: files, seconds: tv.elapsed().as_secs_f64(), rays });
    }
    if let Some(dir) = &a.frames {
        let exposure = first_exposure.unwrap_or(1.0);
        report.images.extend(write_frames(dir, &frames, a.width, a.height, exposure)?);
    }
    report.timings.render = t.elapsed().as_secs_f64();
    report.timings.total = t0.elapsed().as_secs_f64();
    if let Some(p) = &a.solve.report {
        write_atomic(p, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if !a.solve.quiet {
        eprintln!("wrote {} in {:.2} s", report.images.join(", "), report.timings.total);
    }
    Ok(exit_code(stats.stop))
}

/// `dir/stem.ext` → `dir/stem_name.ext`.
fn suffixed(path: &std::path::Path, name: &str) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let file = match path.extension() {
        Some(ext) => format!("{stem}_{name}.{}", ext.to_string_lossy()),
        None => format!("{stem}_{name}"),
    };
    path.with_file_name(file)
}

/// Writes the frames as PNG with one exposure, and frames.json describing them; returns
/// the files written.
fn write_frames(dir: &Path, frames: &[Frame], width: usize, height: usize, exposure: f64) -> Result<Vec<String>> {
    let mut files = Vec::new();
    let mut index = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        let img = Image { width, height, pixels: f.pixels.iter().map(|p| DVec3::from_array(p.map(f64::from))).collect() };
        let name = format!("frame-{:04}.png", k + 1);
        let path = dir.join(&name);
        write_atomic(&path, &output::png::encode(&img, Some(exposure))?)?;
        files.push(path.display().to_string());
        index.push(serde_json::json!({
            "file": name, "iteration": f.iteration, "residual": f.residual,
            "seconds": f.seconds, "rays": f.rays,
        }));
    }
    let json = serde_json::json!({ "exposure": exposure, "frames": index });
    write_atomic(&dir.join("frames.json"), serde_json::to_string_pretty(&json)?.as_bytes())?;
    Ok(files)
}

/// Forwards progress but never asks to stop (used for output after an interrupt).
struct NeverStop<'a>(&'a CliProgress);
impl radiosity::Progress for NeverStop<'_> {
    fn begin(&self, s: &str, t: u64) {
        self.0.begin(s, t)
    }
    fn advance(&self, n: u64) {
        self.0.advance(n)
    }
    fn end(&self) {
        self.0.end()
    }
    fn message(&self, m: &str) {
        self.0.message(m)
    }
}
