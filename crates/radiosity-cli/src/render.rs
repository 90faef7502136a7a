//! `radiosity render`: solve, then draw the scene from a camera.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use glam::DVec3;
use radiosity::output;
use radiosity::pipeline::solve_scene;
use radiosity::render::gouraud::{self, ElementTracer, Shading};
use radiosity::scene::Camera;

use crate::common::{exit_code, write_atomic, SolveFlags};
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
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
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
    /// Samples per pixel along each axis (box filter).
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub spp: usize,
    /// Shading: gouraud (interpolated from vertices) or flat (one value per element).
    #[arg(long, value_name = "MODE", default_value = "gouraud")]
    pub shading: String,
    /// PNG exposure: radiance is multiplied by this before sRGB encoding [default: automatic].
    #[arg(long, value_name = "SCALE")]
    pub exposure: Option<f64>,
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
    if a.width == 0 || a.height == 0 || a.width > 16384 || a.height > 16384 {
        bail!("--width and --height must be between 1 and 16384");
    }
    if a.spp == 0 || a.spp > 64 {
        bail!("--spp must be between 1 and 64");
    }
    let shading = match a.shading.as_str() {
        "gouraud" => Shading::Gouraud,
        "flat" => Shading::Flat,
        s => bail!("unknown --shading '{s}' (known: gouraud, flat)"),
    };
    if let Some(e) = a.exposure {
        if !(e.is_finite() && e > 0.0) {
            bail!("--exposure must be a positive number");
        }
    }
    let file_camera = match &a.camera {
        Some(p) => Some(Camera::load_json(p)?),
        None => None,
    };
    let (scene, load_s) = a.solve.load_scene()?;
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
    cam.validate().map_err(|m| anyhow::anyhow!("camera: {m}"))?;
    let out_png = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.png", scene.name)));

    let progress = CliProgress::new(a.solve.quiet);
    let solved = solve_scene(scene, &settings, &progress)?;
    let stats = &solved.solution.stats;
    if !a.solve.quiet {
        eprintln!(
            "{} elements, {} form factors ({} rays), {} {} iterations, residual {:.2e} ({:?})",
            solved.mesh.len(),
            solved.ff_stats.as_ref().map_or(0, |f| f.nonzeros),
            solved.ff_stats.as_ref().map_or(0, |f| f.rays),
            stats.solver,
            stats.iterations,
            stats.residual,
            stats.stop
        );
    }

    let t = Instant::now();
    let tracer = ElementTracer::new(&solved.mesh);
    let opts = gouraud::Options { width: a.width, height: a.height, spp_axis: a.spp, shading };
    // The image is drawn even after an interrupt: the solution so far is what we have.
    let quiet = CliProgress::new(a.solve.quiet);
    let img = solved.render(&cam, &opts, &tracer, &NeverStop(&quiet));
    let render_s = t.elapsed().as_secs_f64();

    let mut report = solved.report();
    report.timings.load = load_s;
    report.timings.render = render_s;
    write_atomic(&out_png, &output::png::encode(&img, a.exposure)?)?;
    report.images.push(out_png.display().to_string());
    if let Some(p) = &a.exr {
        write_atomic(p, &output::exr::encode(&img)?)?;
        report.images.push(p.display().to_string());
    }
    report.timings.total = t0.elapsed().as_secs_f64();
    if let Some(p) = &a.solve.report {
        write_atomic(p, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if !a.solve.quiet {
        eprintln!("wrote {} in {:.2} s", report.images.join(", "), report.timings.total);
    }
    Ok(exit_code(stats.stop))
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
