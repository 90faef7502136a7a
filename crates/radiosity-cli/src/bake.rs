//! `radiosity bake`: solve a scene and write it with its light baked in, as glTF binary
//! (`.glb`) with per-vertex `COLOR_0` (see `radiosity::output::gltf` for the convention).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use radiosity::mesh::atlas::Atlas;
use radiosity::output::gltf::{auto_exposure, baked_glb, moz_lightmap_png, vertex_colors_glb, Lightmap, LightmapMode, Options};
use radiosity::pipeline::solve_scene;
use radiosity::render::{gather, lightmap};

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
    /// the 97th percentile (by area) of the surfaces' radiance in its brightest channel, so
    /// that saturated colours keep their shading].
    #[arg(long, value_name = "K")]
    pub exposure: Option<f64>,
    /// Also bake a lightmap: a second UV set (TEXCOORD_1) from an automatic atlas, texels
    /// filled by the final gather (sharp shadows whatever the mesh), shown through every
    /// material's emissive texture; the linear radiance is also written beside the GLB as
    /// FILE.lightmap.exr.
    #[arg(long)]
    pub lightmap: bool,
    /// How the lightmap is shown: `emissive` (radiance as every material's emissive
    /// texture over a black base colour: core glTF, the same in every viewer) or `moz`
    /// (irradiance in MOZ_lightmap, multiplied by the materials' own colours and textures,
    /// which are kept: three.js lightMap, Mozilla Hubs; other viewers light the plain
    /// materials themselves).
    #[arg(long, value_name = "MODE", default_value = "emissive")]
    pub lightmap_mode: String,
    /// Lightmap side in texels (8 to 16384).
    #[arg(long, value_name = "N", default_value_t = radiosity::mesh::atlas::DEFAULT_SIZE)]
    pub lightmap_size: usize,
    /// World units per lightmap texel [default: as small as the lightmap allows].
    #[arg(long, value_name = "S")]
    pub texel_size: Option<f64>,
    /// Lightmap texels: shadow rays per emitter, as N × N.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub shadow_rays: usize,
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
    if a.shadow_rays == 0 || a.shadow_rays > 16 {
        bail!("--shadow-rays must be between 1 and 16");
    }
    let mode: LightmapMode = a.lightmap_mode.parse().map_err(|e| anyhow::anyhow!("--lightmap-mode: {e}"))?;
    if !a.lightmap && (a.texel_size.is_some() || a.lightmap_size != radiosity::mesh::atlas::DEFAULT_SIZE || mode != LightmapMode::Emissive)
    {
        bail!("--lightmap-size, --texel-size and --lightmap-mode need --lightmap");
    }
    let exr_path = a.lightmap.then(|| a.output.with_extension("lightmap.exr"));
    let settings = a.solve.settings()?;
    let mut outputs = Outputs::default();
    outputs.add("-o", &a.output);
    if let Some(p) = &exr_path {
        outputs.add("lightmap EXR", p);
    }
    if let Some(p) = &a.solve.report {
        outputs.add("--report", p);
    }
    outputs.check()?;
    a.solve.init_threads()?;
    let (scene, load_s) = a.solve.load_scene()?;
    // The atlas depends on the scene alone: one that cannot fit is refused before the solve.
    let atlas = if a.lightmap {
        let opts = radiosity::mesh::atlas::Options { size: a.lightmap_size, texel: a.texel_size, ..Default::default() };
        Some(Atlas::build(&scene, &opts)?)
    } else {
        None
    };
    let progress = CliProgress::new(a.solve.quiet);
    let solved = solve_scene(scene, &settings, &progress)?;
    let b = solved.solution.display_radiosity();
    let exposure = a.exposure.unwrap_or_else(|| auto_exposure(&solved.scene, &solved.mesh, &b));
    let t = Instant::now();
    // The scene's camera, else the view `render` frames by default, so that viewers open
    // the baked file where an image of it would be taken.
    let camera = solved.scene.camera.unwrap_or_else(|| {
        let (lo, hi) = solved.scene.bounds();
        crate::render::default_camera_inside(&solved.scene, radiosity::scene::Camera::framing(lo, hi), 512, 512, None, true)
    });
    let opts = Options {
        exposure,
        camera: Some(camera),
        generator: format!("radiosity {}", env!("CARGO_PKG_VERSION")),
    };
    let mut lightmap_line = None;
    let mut lightmap_warning = None;
    let (glb, stats) = if let Some(atlas) = &atlas {
        let t_map = Instant::now();
        let axis = solved.default_gather_axis();
        let indirect = solved.indirect(axis > 0);
        let gopts = gather::Options {
            width: atlas.size,
            height: atlas.size,
            spp_axis: 1,
            shadow_axis: a.shadow_rays,
            gather_axis: axis,
            seed: a.solve.seed,
            // One position per texel: nothing to adapt.
            noise: 0.0,
        };
        let (quantity, element_l): (_, Vec<_>) = match mode {
            LightmapMode::Emissive => (lightmap::Quantity::Radiance, b.iter().map(|x| *x / std::f64::consts::PI).collect()),
            LightmapMode::Moz => {
                // Irradiance H = (B − E)/ρ per channel (0 where ρ is).
                let (rho, e) = radiosity::pipeline::element_materials(&solved.scene, &solved.mesh);
                let h = b
                    .iter()
                    .zip(rho.iter().zip(&e))
                    .map(|(b, (r, e))| {
                        let (b, r, e) = (b.to_array(), r.to_array(), e.to_array());
                        radiosity::Rgb::from_array(std::array::from_fn(|c| if r[c] > 0.0 { ((b[c] - e[c]) / r[c]).max(0.0) } else { 0.0 }))
                    })
                    .collect();
                (lightmap::Quantity::Irradiance, h)
            }
        };
        let (img, st) =
            lightmap::render(&solved.scene, &solved.mesh, &solved.rays, &indirect, atlas, &element_l, quantity, &gopts, &progress);
        if radiosity::Progress::should_stop(&progress) {
            return Err(radiosity::Error::Cancelled.into());
        }
        let (png, intensity) = match mode {
            LightmapMode::Emissive => (radiosity::output::png::encode(&img, Some(exposure))?, 1.0),
            LightmapMode::Moz => {
                let rho_ref = radiosity::output::gltf::moz_reference_reflectance(&solved.scene);
                let (png, intensity, clipped) = moz_lightmap_png(&img, exposure, rho_ref)?;
                if clipped > 0 && !a.solve.quiet {
                    eprintln!(
                        "lightmap: {clipped} texels above MOZ_lightmap intensity {intensity:.4e} clipped (at most the brightest 0.1 %, \
                         or light that shows white on surfaces of reflectance {rho_ref:.3} and above; the EXR keeps them)"
                    );
                }
                (png, intensity)
            }
        };
        if let Some(p) = &exr_path {
            write_atomic(p, &radiosity::output::exr::encode(&img)?)?;
        }
        lightmap_line = Some(format!(
            "lightmap {n}² ({}, {}): {} charts, texel {:.4e} scene units, {:.1} % of the texture in charts, {:.1} % covered by surfaces; \
             {} texels gathered, {} dilated, {} flat; {:.2} s",
            exr_path.as_ref().map_or(String::new(), |p| p.display().to_string()),
            match mode {
                LightmapMode::Emissive => "radiance, emissive texture".to_string(),
                LightmapMode::Moz => format!("irradiance, MOZ_lightmap intensity {intensity:.4e}"),
            },
            atlas.charts.len(),
            atlas.texel,
            100.0 * atlas.used(),
            100.0 * atlas.covered(&solved.scene),
            st.shaded,
            st.dilated,
            st.flat,
            t_map.elapsed().as_secs_f64(),
            n = atlas.size,
        ));
        let covered = atlas.covered(&solved.scene);
        if covered < 0.2 {
            lightmap_warning = Some(format!(
                "the surfaces cover only {:.1} % of the lightmap ({} charts, most too small for their padding): \
                 their light is coarse; raise --lightmap-size, or rely on the vertex colours",
                100.0 * covered,
                atlas.charts.len()
            ));
        }
        let lm = Lightmap { atlas, png: &png, mode, intensity };
        baked_glb(&solved.scene, &solved.mesh, &solved.vertex_radiosity, Some(lm), &opts)?
    } else {
        vertex_colors_glb(&solved.scene, &solved.mesh, &solved.vertex_radiosity, &opts)?
    };
    write_atomic(&a.output, &glb)?;
    let mut report = solved.report();
    report.warnings.extend(lightmap_warning.clone());
    report.timings.load = load_s;
    report.timings.render = t.elapsed().as_secs_f64();
    report.images.push(a.output.display().to_string());
    report.timings.stages = progress.stages();
    report.timings.total = t0.elapsed().as_secs_f64();
    if let Some(p) = &a.solve.report {
        write_atomic(p, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if !a.solve.quiet {
        if let Some(e) = &report.energy {
            eprintln!("{}", energy_summary(e));
        }
        if let Some(l) = &lightmap_line {
            eprintln!("{l}");
        }
        if let Some(w) = &lightmap_warning {
            eprintln!("warning: {w}");
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
