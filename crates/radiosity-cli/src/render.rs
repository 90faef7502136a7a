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
use radiosity::render::{lit_coverage, view_coverage, Image, ViewCoverage};
use radiosity::report::ViewReport;
use radiosity::scene::{Camera, Scene};
use radiosity::solve::{IterationState, StopReason};
use radiosity::{NoProgress, Progress as _};

use crate::common::{energy_summary, exit_code, write_atomic, Outputs, SolveFlags};
use crate::progress::CliProgress;

/// The default of `--shadow-rays` (also how the gather-only flags are told to be unset).
const DEFAULT_SHADOW_RAYS: usize = 2;

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
    /// Image width in pixels (1 to 65535; the image must also fit in the memory available).
    #[arg(long, default_value_t = 512, value_parser = parse_side)]
    pub width: usize,
    /// Image height in pixels (1 to 65535).
    #[arg(long, default_value_t = 512, value_parser = parse_side)]
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
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SHADOW_RAYS)]
    pub shadow_rays: usize,
    /// Final gather: indirect rays per pixel sample, as N × N, each reading the reflected
    /// radiosity of the element it meets; 0 interpolates the indirect light from the mesh's
    /// vertices instead (no rays, no noise; as exact as the form factors, as coarse as the
    /// mesh) [default: 2 on the hierarchical transport with a minimum link size (above
    /// 50000 elements) and for the stochastic solvers (4 under a sky without portals, whose direct light
    /// these rays also estimate), 0 on form-factor rows and on a hierarchy refined down to
    /// the elements (where 4 × 4 rays per sample estimate a sky)]
    #[arg(long, value_name = "N")]
    pub gather_rays: Option<usize>,
    /// Final gather, adaptive sampling: a pixel stops taking samples (after 8, in rounds of
    /// 4, up to --spp²) once the standard error of its mean is below this share of it
    /// (pixels darker than a quarter of the image's mean: of that quarter); edges take every
    /// sample; 0 takes every sample in every pixel.
    #[arg(long, value_name = "SHARE", default_value_t = radiosity::render::gather::DEFAULT_NOISE)]
    pub pixel_noise: f64,
    /// PNG exposure: radiance is multiplied by this before sRGB encoding [default: automatic].
    #[arg(long, value_name = "SCALE")]
    pub exposure: Option<f64>,
    /// Also write an image after every solver iteration into this folder (frame-0001.png …
    /// and frames.json): light flowing into the scene bounce by bounce (progressive
    /// refinement: after 1, 2, 4 … shots, then every n shots). Frames are Gouraud previews
    /// of the first view, all at the final image's exposure: with jacobi the sequence
    /// brightens bounce by bounce (chebyshev, the default, takes fewer and larger steps
    /// after its first few); progressive refinement shows its ambient estimate of the
    /// light not yet shot, so its first frames are flat and bright and settle.
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

/// The largest image side accepted at parsing (PNG and EXR themselves allow more; memory
/// is checked separately).
const MAX_SIDE: usize = 65535;

fn parse_side(s: &str) -> Result<usize, String> {
    let n: usize = s.trim().parse().map_err(|_| format!("'{s}' is not a whole number of pixels"))?;
    if n == 0 || n > MAX_SIDE {
        return Err(format!("must be between 1 and {MAX_SIDE} pixels, got {n}"));
    }
    Ok(n)
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
    if a.solve.all_solvers() {
        bail!("--solver all compares solvers: use it with `radiosity solve` (and --plot); render one solver");
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
    if !(a.pixel_noise.is_finite() && (0.0..=1.0).contains(&a.pixel_noise)) {
        bail!("--pixel-noise must be between 0 and 1 (a share of the pixel's value), got {}", a.pixel_noise);
    }
    if a.gather_rays.is_some_and(|g| g > 16) {
        bail!("--gather-rays must be between 0 and 16");
    }
    if !gather {
        let mut set = Vec::new();
        if a.shadow_rays != DEFAULT_SHADOW_RAYS {
            set.push("--shadow-rays");
        }
        if a.gather_rays.is_some() {
            set.push("--gather-rays");
        }
        if a.pixel_noise != radiosity::render::gather::DEFAULT_NOISE {
            set.push("--pixel-noise");
        }
        if !set.is_empty() {
            bail!("{} set the final gather, which --render {} does not use (use --render gather)", set.join(", "), a.mode);
        }
    }
    if let Some(e) = a.exposure {
        if !(e.is_finite() && e > 0.0) {
            bail!("--exposure must be a positive number");
        }
    }
    check_image_memory(&a, spp, gather)?;
    let file_camera = match &a.camera {
        Some(p) => Some(Camera::load_json(p)?),
        None => None,
    };
    let view_list = match &a.views {
        Some(p) => {
            let list = Camera::load_views(p)?;
            for (k, (name, _)) in list.iter().enumerate() {
                if let Some(j) = list[..k].iter().position(|(n, _)| n == name) {
                    bail!(
                        "{}: views {j} and {k} are both named '{name}': view names must be distinct (each names its output files)",
                        p.display()
                    );
                }
            }
            Some(list)
        }
        None => None,
    };
    let names: Vec<String> = match &view_list {
        Some(list) => list.iter().map(|(n, _)| n.clone()).collect(),
        None => vec!["main".to_string()],
    };
    // Outputs are checked before any work: now when -o names the image, else (default name
    // from the scene) right after loading it.
    if let Some(png) = &a.output {
        outputs(&a, png, view_list.is_some(), &names).check()?;
    }
    a.solve.init_threads()?;
    let (scene, load_s) = a.solve.load_scene()?;
    let out_png = a.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.png", scene.name)));
    outputs(&a, &out_png, view_list.is_some(), &names).check()?;
    let mut warnings = Vec::new();
    // The views: one (file, flags, the scene's own camera, or a framing default) or a list.
    let framed = view_list.is_none()
        && file_camera.is_none()
        && scene.camera.is_none()
        && a.eye.is_none()
        && a.look_at.is_none();
    let mut views: Vec<(String, Camera, PathBuf, Option<PathBuf>)> = match view_list {
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
            if framed {
                cam = default_camera_inside(&scene, cam, a.width, a.height, a.fov, a.solve.quiet);
            }
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
    // A camera that sees nothing, or only the backs of one-sided surfaces, draws a black
    // image: said now, before the solve.
    let mut warned = vec![false; views.len()];
    {
        let rays = radiosity::accel::SceneRays::new(&scene.polygons);
        for (k, (name, cam, _, _)) in views.iter().enumerate() {
            let cov = view_coverage(&scene, &rays, cam, a.width, a.height, 64);
            // Under a sky, a view of the sky alone is not black.
            if scene.lit_sky().is_some() && cov.back * 100 < cov.total().max(1) {
                continue;
            }
            if let Some(why) = cov.problem() {
                warned[k] = true;
                let p = cam.position;
                let w = format!("view '{name}': the camera at ({}, {}, {}) {why}", p.x, p.y, p.z);
                eprintln!("warning: {w}");
                warnings.push(w);
            }
        }
    }

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
    let mut report_warnings = Vec::new();
    let tracer =
        tracer_cell.into_inner().unwrap_or_else(|| ElementTracer::new(&solved.mesh, &two_sided_of(&solved.scene)));
    // A camera that sees surfaces, but none of them lit (outside a closed two-sided room),
    // draws a black image too: known only now. The default camera then tries the inside.
    if solved.scene.lit_sky().is_none() {
        let b = solved.lit_radiosity();
        let lit = |cam: &Camera| lit_coverage(&solved.mesh, &tracer, &b, cam, a.width, a.height, 64);
        for (k, (name, cam, _, _)) in views.iter_mut().enumerate() {
            let (seen, total) = lit(cam);
            // The default camera shows lit surfaces in under a quarter of the image: an
            // inside camera that shows at least twice as many is taken.
            if framed && a.frames.is_none() && seen * 4 < total {
                // The same framing from the opposite side (a Cornell box open towards +z)
                // when it shows lit surfaces in a quarter of the image, else the one of it
                // and a camera inside that shows the most, if at least twice as many.
                let scored: Vec<(usize, Camera, &str)> = [
                    opposite_camera(cam).map(|c| (c, "the same view from the opposite side")),
                    inside_camera(&solved.scene, cam, a.fov).map(|c| (c, "a camera inside")),
                ]
                .into_iter()
                .flatten()
                .map(|(c, what)| (lit(&c).0, c, what))
                .collect();
                let best = scored.iter().find(|(n, _, _)| n * 4 >= total).copied().or_else(|| {
                    scored.iter().filter(|(n, _, _)| *n >= 2 * seen.max(1)).max_by_key(|(n, _, _)| *n).copied()
                });
                if let Some((_, better, what)) = best {
                    if !a.solve.quiet {
                        let (o, p) = (cam.position, better.position);
                        eprintln!(
                            "note: the default camera, outside at ({:.4}, {:.4}, {:.4}), sees lit surfaces in {:.1} % of the \
                             image; using {what} at ({:.4}, {:.4}, {:.4}) (--eye/--look-at or --camera choose another)",
                            o.x,
                            o.y,
                            o.z,
                            100.0 * seen as f64 / total as f64,
                            p.x,
                            p.y,
                            p.z
                        );
                    }
                    *cam = better;
                    continue;
                }
            }
            if warned[k] || seen * 100 >= total {
                continue;
            }
            let p = cam.position;
            let w = format!(
                "view '{name}': the camera at ({}, {}, {}) sees lit surfaces in only {:.1} % of the image: the image is \
                 nearly black (is it outside a closed room?); use --camera or --eye/--look-at",
                p.x,
                p.y,
                p.z,
                100.0 * seen as f64 / total as f64
            );
            eprintln!("warning: {w}");
            report_warnings.push(w);
        }
    }
    let gather_rays = a.gather_rays.unwrap_or_else(|| solved.default_gather_axis());
    let indirect = if gather { Some(solved.indirect(gather_rays > 0)) } else { None };
    let mut report = solved.report();
    report.timings.load = load_s;
    report.warnings.extend(warnings);
    report.warnings.extend(report_warnings);
    // After an interrupt during the solve the images are still drawn from the solution so
    // far (a second Ctrl-C aborts); a first Ctrl-C after the solve (while rendering) stops
    // rendering: the view being drawn and those after it are not written, the views done
    // and the report are.
    let quiet = CliProgress::new(a.solve.quiet);
    let render_progress = RenderStop { inner: &quiet, armed: stats.stop != StopReason::Interrupted };
    let mut first_exposure = None;
    for (k, (name, cam, png_path, exr_path)) in views.iter().enumerate() {
        let tv = Instant::now();
        let (img, rays, positions) = match &indirect {
            Some(hv) => {
                let gopts = gather::Options {
                    width: a.width,
                    height: a.height,
                    spp_axis: spp,
                    shadow_axis: a.shadow_rays,
                    gather_axis: gather_rays,
                    seed: a.solve.seed,
                    noise: a.pixel_noise,
                };
                let (img, sampled) = solved.render_gather(cam, &gopts, &tracer, hv, &render_progress);
                (img, sampled.rays, Some(sampled.positions_per_pixel()))
            }
            None => {
                let opts = gouraud::Options { width: a.width, height: a.height, spp_axis: spp, shading };
                let img = solved.render(cam, &opts, &tracer, &render_progress);
                let rays = (a.width * a.height * spp * spp) as u64;
                (img, rays, None)
            }
        };
        if render_progress.should_stop() {
            let w = format!(
                "interrupted while rendering view '{name}': it and the {} view(s) after it were not written",
                views.len() - k - 1
            );
            eprintln!("{w}");
            report.warnings.push(w);
            break;
        }
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
        let indirect = indirect.as_ref().map(|i| match i {
            gather::Indirect::Gathered { .. } => format!("gathered ({gather_rays}×{gather_rays} rays per pixel position)"),
            gather::Indirect::Interpolated(_) => "interpolated from the vertices".to_string(),
        });
        report.views.push(ViewReport {
            name: name.clone(),
            images: files,
            seconds: tv.elapsed().as_secs_f64(),
            rays,
            indirect,
            positions_per_pixel: positions,
        });
    }
    if let Some(dir) = &a.frames {
        let exposure = first_exposure.unwrap_or(1.0);
        report.images.extend(write_frames(dir, &frames, a.width, a.height, exposure)?);
    }
    report.timings.render = t.elapsed().as_secs_f64();
    report.timings.stages = progress.stages();
    report.timings.stages.extend(quiet.stages());
    report.timings.total = t0.elapsed().as_secs_f64();
    if let Some(p) = &a.solve.report {
        write_atomic(p, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if !a.solve.quiet {
        let images = if report.images.is_empty() { "no image".to_string() } else { report.images.join(", ") };
        // Adaptive sampling at work: the samples the pixels took, on average over the views.
        let taken: Vec<f64> = report.views.iter().filter_map(|v| v.positions_per_pixel).collect();
        let samples = if taken.is_empty() {
            String::new()
        } else {
            let mean = taken.iter().sum::<f64>() / taken.len() as f64;
            format!(" ({mean:.1} of {} samples per pixel on average)", spp * spp)
        };
        eprintln!("wrote {images} in {:.2} s{samples}", report.timings.total);
    }
    Ok(exit_code(stats.stop))
}

/// Every file the run will write, for the check before any work.
fn outputs(a: &RenderArgs, png: &Path, list: bool, names: &[String]) -> Outputs {
    let mut o = Outputs::default();
    for name in names {
        let (p, e) = if list {
            (suffixed(png, name), a.exr.as_ref().map(|e| suffixed(e, name)))
        } else {
            (png.to_path_buf(), a.exr.clone())
        };
        o.add_format(if a.output.is_some() { "-o" } else { "the image (default name)" }, &p, "png", "PNG");
        if let Some(e) = e {
            o.add_format("--exr", &e, "exr", "OpenEXR");
        }
    }
    if let Some(r) = &a.solve.report {
        o.add("--report", r);
    }
    if let Some(d) = &a.frames {
        o.add("--frames", &d.join("frames.json"));
    }
    o
}

/// Refuses an image whose buffers (for one view at a time: the radiance image, the
/// renderer's own buffers, tone mapping and the encoders; with --frames one frame more)
/// need more memory than is available now.
fn check_image_memory(a: &RenderArgs, spp: usize, gather: bool) -> Result<()> {
    let (w, h) = (a.width, a.height);
    let pixels = (w as u64).saturating_mul(h as u64);
    // Tone mapping (luminances, 8 B), 8-bit RGB and its compressed PNG (≤ 6 B), the EXR's f32
    // channels and file (24 B), per pixel.
    let encoders = pixels.saturating_mul(8 + 6 + if a.exr.is_some() { 24 } else { 0 });
    let mut needed = radiosity::render::image_memory_bytes(w, h, spp, gather).saturating_add(encoders);
    if a.frames.is_some() {
        // The frame being drawn plus one kept (f32 RGB); more frames add 12 B per pixel each.
        needed = needed
            .saturating_add(radiosity::render::image_memory_bytes(w, h, spp.min(3), false))
            .saturating_add(pixels.saturating_mul(12));
    }
    if let Some(available) = radiosity::transport::available_memory() {
        if needed > available {
            return Err(radiosity::Error::TooLarge {
                what: format!(
                    "rendering a {w}×{h} image ({}, {spp}×{spp} samples per pixel; one view at a time)",
                    if gather { "gather" } else { a.mode.as_str() }
                ),
                needed,
                limit: available,
                hint: "the limit is the memory available now; use a smaller --width/--height or --spp".into(),
            }
            .into());
        }
    }
    Ok(())
}

/// The framing default for a scene without a camera looks at it from outside; for a closed
/// room (every ray from there meets the backs of its one-sided walls) a camera inside the
/// bounding box, on the same line of sight, is used when it sees more.
pub(crate) fn default_camera_inside(scene: &Scene, outside: Camera, width: usize, height: usize, fov: Option<f64>, quiet: bool) -> Camera {
    let rays = radiosity::accel::SceneRays::new(&scene.polygons);
    let before = view_coverage(scene, &rays, &outside, width, height, 64);
    if before.problem().is_none() || before.back * 100 < before.total() {
        return outside;
    }
    // The same framing from the opposite side first (a box open on the far side), then a
    // camera inside (a closed room): the one that sees the most front faces.
    // The opposite side is taken when its view has no problem.
    let scored: Vec<(ViewCoverage, Camera, &str)> = [
        opposite_camera(&outside).map(|c| (c, "the same view from the opposite side")),
        inside_camera(scene, &outside, fov).map(|c| (c, "a camera inside")),
    ]
    .into_iter()
    .flatten()
    .map(|(c, what)| (view_coverage(scene, &rays, &c, width, height, 64), c, what))
    .collect();
    let best = scored.iter().find(|(v, _, _)| v.problem().is_none()).or_else(|| {
        scored.iter().filter(|(v, _, _)| v.front > before.front).max_by_key(|(v, _, _)| v.front)
    });
    let Some((_, better, what)) = best.map(|(v, c, w)| (v.front, *c, *w)) else { return outside };
    if !quiet {
        let (o, p) = (outside.position, better.position);
        eprintln!(
            "note: the default camera, outside the scene at ({:.4}, {:.4}, {:.4}), sees mostly the backs of its one-sided \
             surfaces; using {what} at ({:.4}, {:.4}, {:.4}) (--eye/--look-at or --camera choose another)",
            o.x, o.y, o.z, p.x, p.y, p.z
        );
    }
    better
}

/// `outside` turned half a turn about the up axis through the point it looks at: the same
/// framing seen from the other side.
fn opposite_camera(outside: &Camera) -> Option<Camera> {
    let up = outside.up.normalize_or_zero();
    let d = outside.position - outside.look_at;
    // Keep the part along up, reverse the rest.
    let along = up * d.dot(up);
    let turned = Camera { position: outside.look_at + along - (d - along), ..*outside };
    turned.validate().ok().map(|_| turned)
}

/// A camera inside the scene's bounding box on the line of sight of `outside` (from 0.8 of
/// the way from the centre to the box, backwards, towards the centre).
fn inside_camera(scene: &Scene, outside: &Camera, fov: Option<f64>) -> Option<Camera> {
    let (lo, hi) = scene.bounds();
    let centre = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo);
    let dir = (outside.look_at - outside.position).normalize();
    // Distance from the centre to the box along the line of sight, backwards.
    let t = (0..3).filter(|&i| dir[i].abs() > 1e-12).map(|i| half[i] / dir[i].abs()).fold(f64::INFINITY, f64::min);
    if !t.is_finite() {
        return None;
    }
    let vfov_deg = fov.unwrap_or(60.0);
    let inside = Camera { position: centre - dir * (0.8 * t), look_at: centre + dir * t, up: outside.up, vfov_deg };
    inside.validate().ok().map(|_| inside)
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

/// Rendering's progress: forwards to the bars and stops on a Ctrl-C pressed after the solve
/// (`armed`), not on one that stopped the solve (its images are still drawn).
struct RenderStop<'a> {
    inner: &'a CliProgress,
    armed: bool,
}
impl radiosity::Progress for RenderStop<'_> {
    fn begin(&self, s: &str, t: u64) {
        self.inner.begin(s, t)
    }
    fn advance(&self, n: u64) {
        self.inner.advance(n)
    }
    fn end(&self) {
        self.inner.end()
    }
    fn message(&self, m: &str) {
        self.inner.message(m)
    }
    fn should_stop(&self) -> bool {
        self.armed && crate::progress::stopped()
    }
}
