//! `radiosity bake`: solve a scene and write it with its light baked in, as glTF binary
//! (`.glb`) with per-vertex `COLOR_0` (see `radiosity::output::gltf` for the convention).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use radiosity::output::gltf::{auto_exposure, vertex_colors_glb, Options};
use radiosity::pipeline::solve_scene;

use crate::common::{energy_summary, exit_code, write_atomic, Outputs, SolveFlags};
use crate::progress::CliProgress;

/// Flags of `radiosity bake`.
#[derive(Args, Debug)]
pub struct BakeArgs {
    #[command(flatten)]
    pub solve: SolveFlags,
    /// The baked scene, glTF binary (.glb): the solved mesh, one node per object, the
    /// radiance times the exposure (clipped to 1, as a display shows it) in per-vertex
    /// COLOR_0 under KHR_materials_unlit.
    #[arg(short, long, value_name = "FILE.glb")]
    pub output: PathBuf,
    /// Radiance is multiplied by this before it is written [default: automatic, 0.8 over
    /// the 97th percentile of the surfaces' radiance, as `render` picks for images].
    #[arg(long, value_name = "K")]
    pub exposure: Option<f64>,
}

pub fn run(a: BakeArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    if let Some(e) = a.exposure {
        if !(e.is_finite() && e > 0.0) {
            bail!("--exposure must be a positive number");
        }
    }
    match a.output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase) {
        Some(e) if e == "glb" => {}
        _ => bail!("-o {}: bake writes glTF binary; name the file .glb", a.output.display()),
    }
    let settings = a.solve.settings()?;
    let mut outputs = Outputs::default();
    outputs.add("-o", &a.output);
    if let Some(p) = &a.solve.report {
        outputs.add("--report", p);
    }
    outputs.check()?;
    a.solve.init_threads()?;
    let (scene, load_s) = a.solve.load_scene()?;
    let progress = CliProgress::new(a.solve.quiet);
    let solved = solve_scene(scene, &settings, &progress)?;
    let b = solved.solution.display_radiosity();
    let exposure = a.exposure.unwrap_or_else(|| auto_exposure(&solved.scene, &solved.mesh, &b));
    let t = Instant::now();
    let opts = Options {
        exposure,
        camera: solved.scene.camera.clone(),
        generator: format!("radiosity {}", env!("CARGO_PKG_VERSION")),
    };
    let (glb, stats) = vertex_colors_glb(&solved.scene, &solved.mesh, &solved.vertex_radiosity, &opts)?;
    write_atomic(&a.output, &glb)?;
    let mut report = solved.report();
    report.timings.load = load_s;
    report.timings.render = t.elapsed().as_secs_f64();
    report.images.push(a.output.display().to_string());
    report.timings.total = t0.elapsed().as_secs_f64();
    if let Some(p) = &a.solve.report {
        write_atomic(p, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if !a.solve.quiet {
        if let Some(e) = &report.energy {
            eprintln!("{}", energy_summary(e));
        }
        eprintln!(
            "wrote {} ({} triangles, {} vertices, {:.1} MB) at exposure {exposure:.4e}{} in {:.2} s",
            a.output.display(),
            stats.triangles,
            stats.vertices,
            glb.len() as f64 / 1e6,
            if stats.clipped > 0 {
                format!(" ({} of {} colour channels clipped to 1; lower --exposure to keep them)", stats.clipped, 3 * stats.vertices)
            } else {
                String::new()
            },
            report.timings.total
        );
    }
    Ok(exit_code(solved.solution.stats.stop))
}
