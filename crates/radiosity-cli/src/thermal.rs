//! `radiosity thermal`: net radiative heat exchange between grey surfaces at given
//! temperatures or heat fluxes (the net-radiation method on our view factors; see
//! `radiosity::thermal`). Boundary conditions come from the scene's materials (TOML
//! `[materials.NAME]` `emissivity`, `temperature`, `heat_flux`, `adiabatic`); the table
//! goes to the terminal, `-o FILE.csv` / `--json FILE` write it.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use radiosity::form_factor;
use radiosity::output::matrix::{MatrixFormat, MatrixMeta, MatrixWriter};
use radiosity::scene::{self, Scene};
use radiosity::thermal::{exchange_factors, solve, viewht, Settings};
use radiosity::view_factors::{Per, Settings as VfSettings};

use crate::common::FormFactorTuning;
use crate::progress::CliProgress;

/// Flags of `radiosity thermal`.
#[derive(Args, Debug)]
pub struct ThermalArgs {
    /// Scene: a TOML file whose materials give emissivity and temperature, heat_flux or
    /// adiabatic, a .vs3 file (with --temperatures), or a View3D view-factor file (.txt/.vf,
    /// as View3D or `radiosity viewfactors` write it) with --temperatures: ViewHT's table.
    pub scene: String,
    /// ViewHT temperature file: lines `first last T` set surfaces first..=last (1-based, in
    /// object order, obstructions not counted) to T kelvin; `0` ends the data. Overrides
    /// the materials' boundary conditions for those surfaces.
    #[arg(long, value_name = "FILE")]
    pub temperatures: Option<PathBuf>,
    /// Temperature of the environment that receives what leaves the geometry, kelvin.
    #[arg(long, value_name = "K", default_value_t = 0.0)]
    pub environment: f64,
    /// Split the spectrum at these wavelengths (µm, increasing) and solve band by band, for
    /// materials with one emissivity per band (TOML `emissivity = [ε₁, ε₂, …]`); overrides
    /// the scene's `[thermal] band_edges`. `--bands none`: grey.
    #[arg(long, value_name = "UM,UM,...")]
    pub bands: Option<String>,
    /// Form-factor method: hemicube, analytic, point-sampled, monte-carlo, adaptive.
    #[arg(long, value_name = "METHOD", default_value = "point-sampled")]
    pub method: String,
    /// Element size in scene units; 0 = the input polygons [default: scene diagonal / 40].
    #[arg(long, value_name = "S")]
    pub mesh_size: Option<f64>,
    /// Enforce reciprocity and closure of the view factors (closed geometry only): the
    /// heat balance then closes to rounding.
    #[arg(long)]
    pub enclosure: bool,
    /// Treat every surface as two-sided (each side its own surface).
    #[arg(long)]
    pub two_sided: bool,
    /// Point-sampled: visibility rays per receiver point (n × n).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub visibility_samples: usize,
    #[command(flatten)]
    pub ff: FormFactorTuning,
    /// Seed for every random choice.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Write the table as CSV here.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Write the table and the balance as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write Gebhart's absorption factors B_IJ between surfaces here (format by extension:
    /// .csv, .npy, .json, .txt/.vf), with each surface's share lost to the environment.
    #[arg(long, value_name = "FILE")]
    pub gebhart: Option<PathBuf>,
    /// Write the radiative conductances GR_IJ = ε_I A_I B_IJ here (Q_IJ = σ GR_IJ (T_I⁴ − T_J⁴)).
    #[arg(long, value_name = "FILE")]
    pub conductances: Option<PathBuf>,
    /// No progress bars or messages (errors and warnings still print).
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: ThermalArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let method: form_factor::Method = a.method.parse()?;
    if let Some(s) = a.mesh_size {
        if !(s.is_finite() && s >= 0.0) {
            bail!("--mesh-size must be a non-negative number, got {s}");
        }
    }
    let ff = a.ff.options(method, a.seed, a.visibility_samples)?;
    let mut outputs = crate::common::Outputs::default();
    if let Some(p) = &a.output {
        outputs.add("-o", p);
    }
    if let Some(p) = &a.json {
        outputs.add("--json", p);
    }
    if let Some(p) = &a.gebhart {
        outputs.add("--gebhart", p);
    }
    if let Some(p) = &a.conductances {
        outputs.add("--conductances", p);
    }
    for p in [&a.gebhart, &a.conductances].into_iter().flatten() {
        if MatrixFormat::from_path(p).is_none() {
            bail!("{}: cannot tell the format from the extension (use .csv, .npy, .json, .txt or .vf)", p.display());
        }
    }
    let band_edges = match a.bands.as_deref() {
        None => None,
        Some("none") | Some("") => Some(Vec::new()),
        Some(s) => Some(
            s.split(',')
                .map(|x| x.trim().parse::<f64>().map_err(|_| anyhow::anyhow!("--bands: '{x}' is not a wavelength in µm")))
                .collect::<Result<Vec<f64>>>()?,
        ),
    };
    if let Some(e) = &band_edges {
        radiosity::thermal::bands::check_edges(e).map_err(|e| anyhow::anyhow!("--bands: {e}"))?;
    }
    outputs.check()?;
    crate::common::init_threads(a.threads)?;
    let path = Path::new(&a.scene);
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default();
    if ext == "txt" || ext == "vf" {
        return viewht(&a, path, t0);
    }
    let (mut desc, vs3) = if ext == "vs3" {
        let (d, c) = scene::vs3::read_vs3(path)?;
        (d, Some(c))
    } else {
        (scene::load(&a.scene)?, None)
    };
    if let Some(p) = &a.temperatures {
        let n = radiosity::thermal::surface_objects(&desc).len();
        let t = viewht::load_temperatures(p, n)?;
        // A .vs3 file gives no boundary conditions of its own: the file must set them all.
        let (set, unset): (Vec<usize>, Vec<usize>) = (1..=n).partition(|&k| t[k - 1].is_some());
        if vs3.is_some() && !unset.is_empty() {
            bail!(
                "{}: gives temperatures to surfaces {} of the {n} in {}, which has no other boundary conditions: \
                 surfaces {} need one too (lines 'first last T', 1-based)",
                p.display(),
                if set.is_empty() { "none".to_string() } else { number_ranges(&set) },
                path.display(),
                number_ranges(&unset)
            );
        }
        radiosity::thermal::set_temperatures(&mut desc, &t)?;
    }
    let enclosure = a.enclosure || vs3.as_ref().is_some_and(|c| c.enclosure);
    if enclosure && !a.enclosure && !a.quiet {
        eprintln!("the .vs3 file asks for the enclosure correction (encl=1)");
    }
    desc.two_sided |= a.two_sided;
    let scene = Scene::from_desc(desc)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let settings = Settings {
        view_factors: VfSettings { per: Per::Element, mesh_size: a.mesh_size, form_factors: ff, enclosure },
        environment: a.environment,
        band_edges,
    };
    let progress = CliProgress::new(a.quiet);
    let exchange = if a.gebhart.is_some() || a.conductances.is_some() {
        Some(exchange_factors(scene.clone(), &settings, &progress)?)
    } else {
        None
    };
    let th = solve(scene, &settings, &progress)?;
    println!(
        "{:<24} {:>10} {:>10} {:>6} {:>10} {:>12} {:>12} {:>12} {:>12}",
        "surface", "condition", "area", "eps", "T [K]", "q [W/m2]", "Q [W]", "J [W/m2]", "G [W/m2]"
    );
    for s in &th.surfaces {
        println!(
            "{:<24} {:>10} {:>10.4e} {:>6.3} {:>10.3} {:>12.5e} {:>12.5e} {:>12.5e} {:>12.5e}",
            s.name, s.boundary, s.area, s.emissivity, s.temperature, s.heat_flux, s.heat, s.radiosity, s.irradiance
        );
    }
    if !th.band_edges.is_empty() {
        let lows = std::iter::once(0.0).chain(th.band_edges.iter().copied());
        let highs = th.band_edges.iter().map(|e| format!("{e}")).chain(std::iter::once("inf".to_string()));
        let names: Vec<String> = lows.zip(highs).map(|(lo, hi)| format!("{lo}-{hi} um")).collect();
        println!("net heat leaving per band [W]:");
        println!("{:<24} {}", "surface", names.iter().map(|n| format!("{n:>14}")).collect::<String>());
        for s in &th.surfaces {
            println!("{:<24} {}", s.name, s.band_heat.iter().map(|q| format!("{q:>14.5e}")).collect::<String>());
        }
    }
    println!(
        "environment at {} K receives {:.5e} W; balance ΣQ − Q_env = {:.3e} W ({:.1e} of Σ|Q|); {} elements, {:.2} s",
        a.environment,
        th.environment_heat,
        th.balance,
        if th.total > 0.0 { th.balance.abs() / th.total } else { 0.0 },
        th.elements,
        t0.elapsed().as_secs_f64()
    );
    if let Some(p) = &a.output {
        let mut s = String::from("surface,condition,area,emissivity,temperature_K,heat_flux,heat_W,radiosity,irradiance");
        for b in 0..th.band_edges.len() + usize::from(!th.band_edges.is_empty()) {
            s += &format!(",heat_W_band{}", b + 1);
        }
        s.push('\n');
        for r in &th.surfaces {
            s += &format!(
                "\"{}\",{},{:e},{},{},{:e},{:e},{:e},{:e}{}\n",
                r.name.replace('"', "\"\""),
                r.boundary,
                r.area,
                r.emissivity,
                r.temperature,
                r.heat_flux,
                r.heat,
                r.radiosity,
                r.irradiance,
                r.band_heat.iter().map(|q| format!(",{q:e}")).collect::<String>()
            );
        }
        crate::common::write_atomic(p, s.as_bytes())?;
    }
    if let Some(p) = &a.json {
        let v = serde_json::json!({
            "surfaces": th.surfaces, "environment_K": a.environment, "environment_heat_W": th.environment_heat,
            "balance_W": th.balance, "total_W": th.total, "elements": th.elements, "band_edges_um": th.band_edges,
            "view_factors": th.diagnostics, "enclosure": th.enclosure,
        });
        crate::common::write_atomic(p, serde_json::to_string_pretty(&v)?.as_bytes())?;
    }
    if let Some(x) = &exchange {
        let n = x.names.len();
        let meta = MatrixMeta {
            title: &a.scene,
            names: &x.names,
            areas: &x.areas,
            emissivity: &x.emissivity,
            method: &a.method,
            per: "object",
            enclosure,
            emittances: false,
        };
        let mut extra = serde_json::Map::new();
        extra.insert("to_environment".into(), serde_json::json!(x.to_environment));
        extra.insert("reciprocity".into(), serde_json::json!(x.reciprocity));
        for (path, m) in [(&a.gebhart, &x.gebhart), (&a.conductances, &x.conductance)] {
            let Some(p) = path else { continue };
            let format = MatrixFormat::from_path(p).unwrap_or(MatrixFormat::Csv);
            crate::common::write_atomic_with(p, |file| {
                let mut w = MatrixWriter::begin(format, file, &meta)?;
                for i in 0..n {
                    w.row(&m[i * n..(i + 1) * n])?;
                }
                w.finish(&extra)?;
                Ok(())
            })?;
        }
        if !a.quiet {
            eprintln!(
                "exchange factors: {n} surfaces, largest reciprocity error of ε A B {:.1e}, rows lose {:.2e} at most to the environment",
                x.reciprocity,
                x.to_environment.iter().fold(0.0f64, |m, v| m.max(*v))
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// ViewHT: a View3D view-factor file and a temperature file give each surface's flux.
fn viewht(a: &ThermalArgs, path: &Path, t0: Instant) -> Result<ExitCode> {
    let Some(tp) = &a.temperatures else {
        bail!("{}: a view-factor file needs --temperatures FILE (ViewHT's 'first last T' lines)", path.display());
    };
    if a.gebhart.is_some() || a.conductances.is_some() {
        bail!("--gebhart/--conductances need a scene; a view-factor file carries one matrix already");
    }
    let vf = viewht::load_view_factor_file(path)?;
    let t = viewht::load_temperatures(tp, vf.len())?;
    let missing: Vec<String> =
        t.iter().enumerate().filter(|(_, t)| t.is_none()).map(|(k, _)| (k + 1).to_string()).collect();
    if !missing.is_empty() {
        bail!("{}: no temperature for surface(s) {}", tp.display(), missing.join(", "));
    }
    let t: Vec<f64> = t.into_iter().flatten().collect();
    let table = viewht::heat_table(&vf, &t, a.environment)?;
    if !a.quiet && table.formed_exchange {
        eprintln!(
            "{}: geometric view factors (didemit = 0): grey exchange formed from the file's emissivities",
            path.display()
        );
    }
    println!("{:>5} {:>12} {:>6} {:>10} {:>12} {:>12}", "srf", "area", "eps", "T [K]", "q [W/m2]", "Q [W]");
    for (k, r) in table.rows.iter().enumerate() {
        println!(
            "{:>5} {:>12.5e} {:>6.3} {:>10.3} {:>12.5e} {:>12.5e}",
            k + 1,
            r.area,
            r.emissivity,
            r.temperature,
            r.heat_flux,
            r.heat
        );
    }
    println!(
        "environment at {} K receives {:.5e} W; balance ΣQ − Q_env = {:.3e} W ({:.1e} of Σ|Q|); \
         reciprocity of A·F {:.1e}; {:.2} s (q > 0: the surface loses heat)",
        a.environment,
        table.environment_heat,
        table.balance,
        if table.total > 0.0 { table.balance.abs() / table.total } else { 0.0 },
        table.reciprocity,
        t0.elapsed().as_secs_f64()
    );
    if let Some(p) = &a.output {
        let mut s = String::from("surface,area,emissivity,temperature_K,heat_flux,heat_W\n");
        for (k, r) in table.rows.iter().enumerate() {
            s += &format!("{},{:e},{},{},{:e},{:e}\n", k + 1, r.area, r.emissivity, r.temperature, r.heat_flux, r.heat);
        }
        crate::common::write_atomic(p, s.as_bytes())?;
    }
    if let Some(p) = &a.json {
        let v = serde_json::json!({
            "surfaces": table.rows, "environment_K": a.environment, "environment_heat_W": table.environment_heat,
            "balance_W": table.balance, "total_W": table.total, "reciprocity": table.reciprocity,
            "emittance_weighted_input": vf.emittances,
        });
        crate::common::write_atomic(p, serde_json::to_string_pretty(&v)?.as_bytes())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Sorted 1-based numbers as ranges: `1, 6–101`.
fn number_ranges(k: &[usize]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < k.len() {
        let mut j = i;
        while j + 1 < k.len() && k[j + 1] == k[j] + 1 {
            j += 1;
        }
        out.push(if j == i { k[i].to_string() } else { format!("{}–{}", k[i], k[j]) });
        i = j + 1;
    }
    out.join(", ")
}
