//! `radiosity viewfactors`: the view-factor matrix of a scene, for thermal work.
//!
//! `F[i][j]` is the fraction of the energy leaving surface `i` that reaches surface `j`
//! (occlusion included except with `--method analytic`). The output format follows the
//! extension of `-o` (`.csv`, `.npy`, `.json`, `.txt`/`.vf` for View3D's text format) or
//! `--format`. The matrix is held once in memory (checked first) and streamed to the file;
//! a per-element matrix too large for memory is streamed row by row as it is computed
//! (reciprocity then cannot be checked, and `--enclosure` is refused). A View3D `.vs3`
//! scene with `encl=1` gets the enclosure correction unless `--no-enclosure`.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use radiosity::form_factor::{self, diagnostics::Diagnostics};
use radiosity::form_factor::sparse::Truncation;
use radiosity::output::matrix::{write_sparse, MatrixFormat, MatrixMeta, MatrixWriter, SparseFormat};
use radiosity::scene::{self, Scene};
use radiosity::view_factors::{Job, Per, Settings};
use radiosity::Error;
use serde_json::{json, Map, Value};

use crate::common::FormFactorTuning;
use crate::progress::CliProgress;

/// Flags of `radiosity viewfactors`.
#[derive(Args, Debug)]
pub struct ViewfactorsArgs {
    /// Scene: a file (.obj, .gltf, .glb, .toml, .vs3) or a built-in name (cornell, furnace).
    pub scene: String,
    /// Output file; the format follows its extension (.csv, .npy, .json, .txt or .vf).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Output format (csv, npy, json, view3d), overriding the extension.
    #[arg(long, value_name = "FORMAT")]
    pub format: Option<String>,
    /// Form-factor method: hemicube, analytic, point-sampled, monte-carlo, adaptive.
    #[arg(long, value_name = "METHOD", default_value = "adaptive")]
    pub method: String,
    /// Rows and columns: input objects (OBJ o/g groups, View3D surfaces) or mesh elements.
    #[arg(long, value_name = "UNIT", default_value = "object")]
    pub per: String,
    /// Element size in scene units; 0 = the input polygons [default: the input polygons
    /// for analytic/adaptive per object, else scene diagonal / 40].
    #[arg(long, value_name = "S")]
    pub mesh_size: Option<f64>,
    /// Enforce reciprocity and closure (closed geometry only) and report the change.
    #[arg(long, conflicts_with = "no_enclosure")]
    pub enclosure: bool,
    /// Do not apply the enclosure correction a .vs3 file asks for (encl=1).
    #[arg(long)]
    pub no_enclosure: bool,
    /// Write View3D's emittance-weighted factors ℱ_ij = ε_i B_ij (Gebhart's B: emission of i
    /// absorbed by j after diffuse reflections; emissivity = 1 − reflectance) instead of F,
    /// as a .vs3 file's emit=1 asks.
    #[arg(long, conflicts_with = "no_emittances")]
    pub emittances: bool,
    /// Write plain F even where a .vs3 file asks for emittance-weighted factors (emit=1).
    #[arg(long)]
    pub no_emittances: bool,
    /// Write a sparse matrix: entries below T dropped (a pair is kept when either of its two
    /// factors reaches T) and the rest rebalanced so that reciprocity stays exact and every
    /// row keeps its sum; format by extension: .mtx (Matrix Market), .csv (triplets), .json.
    #[arg(long, value_name = "T")]
    pub sparse_threshold: Option<f64>,
    /// Treat every surface as two-sided (each side gets its own row).
    #[arg(long)]
    pub two_sided: bool,
    /// Refuse a reflectance ≥ 1 (e.g. glTF's default white) instead of lowering it to 0.95.
    #[arg(long)]
    pub strict: bool,
    /// Point-sampled: visibility rays per receiver point (n × n).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub visibility_samples: usize,
    #[command(flatten)]
    pub ff: FormFactorTuning,
    /// Seed for every random choice (results do not depend on --threads).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Memory the matrix may use (e.g. 8G, 512M) [default: what the system has available].
    #[arg(long, value_name = "SIZE")]
    pub memory_limit: Option<String>,
    /// Compare with a reference matrix (JSON with names and matrix, or faces and F_i_to_j)
    /// and report the largest absolute difference.
    #[arg(long, value_name = "FILE")]
    pub compare: Option<PathBuf>,
    /// Write timings and diagnostics as JSON here.
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// No progress bars or messages (errors and warnings still print).
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: ViewfactorsArgs) -> Result<ExitCode> {
    match run_inner(&a) {
        Err(e) if matches!(e.downcast_ref::<Error>(), Some(Error::Cancelled)) => {
            eprintln!("interrupted: no matrix written");
            Ok(ExitCode::from(130))
        }
        r => r,
    }
}

fn run_inner(a: &ViewfactorsArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let method: form_factor::Method = a.method.parse()?;
    let per: Per = a.per.parse()?;
    let sparse = match a.sparse_threshold {
        None => None,
        Some(t) if !(t.is_finite() && t >= 0.0) => bail!("--sparse-threshold must be a number ≥ 0, got {t}"),
        Some(t) => {
            if a.format.is_some() {
                bail!("--format does not apply to a sparse matrix: its format follows the extension (.mtx, .csv, .json)");
            }
            let f = SparseFormat::from_path(&a.output).with_context(|| {
                format!("{}: a sparse matrix is written as .mtx (Matrix Market), .csv (triplets) or .json", a.output.display())
            })?;
            Some((f, t))
        }
    };
    let format = match (&a.format, sparse) {
        (_, Some(_)) => MatrixFormat::Csv, // unused
        (Some(f), None) => f.parse()?,
        (None, None) => MatrixFormat::from_path(&a.output).with_context(|| {
            format!("{}: cannot tell the format from the extension (use .csv, .npy, .json, .txt/.vf or --format)", a.output.display())
        })?,
    };
    if let Some(s) = a.mesh_size {
        if !(s.is_finite() && s >= 0.0) {
            bail!("--mesh-size must be a non-negative number, got {s}");
        }
    }
    let memory_limit = a.memory_limit.as_deref().map(parse_size).transpose()?;
    let ff = a.ff.options(method, a.seed, a.visibility_samples)?;
    let mut outputs = crate::common::Outputs::default();
    outputs.add("-o", &a.output);
    if let Some(p) = &a.report {
        outputs.add("--report", p);
    }
    outputs.check()?;
    crate::common::init_threads(a.threads)?;

    // Scene (a .vs3 file also carries its control values).
    let (mut desc, vs3) = if Path::new(&a.scene).extension().is_some_and(|e| e.eq_ignore_ascii_case("vs3")) {
        let (d, c) = scene::vs3::read_vs3(Path::new(&a.scene))?;
        (d, Some(c))
    } else {
        (scene::load(&a.scene)?, None)
    };
    desc.two_sided |= a.two_sided;
    desc.strict = a.strict;
    let scene = Scene::from_desc(desc)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let enclosure = a.enclosure || (vs3.as_ref().is_some_and(|c| c.enclosure) && !a.no_enclosure);
    if enclosure && !a.enclosure && !a.quiet {
        eprintln!("the .vs3 file asks for the enclosure correction (encl=1); --no-enclosure to skip it");
    }
    let emittances = a.emittances || (vs3.as_ref().is_some_and(|c| c.emittances) && !a.no_emittances);
    if emittances && !a.emittances && !a.quiet {
        eprintln!("the .vs3 file asks for emittance-weighted factors (emit=1); --no-emittances for plain F");
    }
    let title = vs3.as_ref().map(|c| c.title.clone()).filter(|t| !t.is_empty()).unwrap_or_else(|| scene.name.clone());
    let settings = Settings { per, mesh_size: a.mesh_size, form_factors: ff, enclosure };
    let job = Job::new(scene, settings)?;
    let progress = CliProgress::new(a.quiet);
    let limit = memory_limit.or_else(radiosity::transport::available_memory);
    let stream = per == Per::Element && !enclosure && !emittances && limit.is_some_and(|l| job.dense_bytes() > l);
    if emittances && job.len() > radiosity::thermal::MAX_ELEMENTS / 4 {
        bail!(
            "{} rows: emittance-weighted factors solve a dense {0} × {0} system with as many right-hand sides, \
             at most {} rows (use --per object or a larger --mesh-size)",
            job.len(),
            radiosity::thermal::MAX_ELEMENTS / 4
        );
    }
    if !a.quiet {
        eprintln!(
            "{}: {} {}s from {} surfaces, method {}{}",
            a.scene,
            job.len(),
            per.name(),
            job.elements(),
            method.name(),
            if stream { " (streamed: the matrix does not fit in memory)" } else { "" }
        );
    }
    let names = job.names();
    let areas = job.areas();
    let emissivity = job.emissivity();
    let meta = MatrixMeta {
        title: &title,
        names: &names,
        areas: &areas,
        emissivity: &emissivity,
        method: method.name(),
        per: per.name(),
        enclosure,
        emittances,
    };
    let t1 = Instant::now();
    let mut extra = Map::new();
    let (diagnostics, stats, comparison) = if stream {
        let (d, stats) = if let Some((sf, t)) = sparse {
            let mut tr = Truncation::new(&areas, t)?;
            let (d, stats) = job.stream(&progress, &mut |row| {
                tr.push(row);
                Ok(())
            })?;
            extra.insert("diagnostics".into(), json!(d));
            extra.insert("form_factors".into(), json!(stats));
            write_truncated(a, sf, tr, &meta, &mut extra)?;
            (d, stats)
        } else {
            let mut w = None;
            write_atomic_stream(&a.output, |file| {
            let mut mw = MatrixWriter::begin(format, file, &meta)?;
            let (d, stats) = job.stream(&progress, &mut |row| mw.row(row).map_err(|e| Error::io(&a.output, e)))?;
            w = Some((d.clone(), stats.clone()));
            extra.insert("diagnostics".into(), json!(d));
            extra.insert("form_factors".into(), json!(stats));
            mw.finish(&extra)?;
            Ok(())
        })
        .and_then(|_| w.context("no result"))?
        };
        (d, stats, None)
    } else {
        let vf = job.compute(memory_limit, &progress)?;
        let comparison = a.compare.as_deref().map(|p| compare(p, &vf.names, &vf.matrix)).transpose()?;
        extra.insert("diagnostics".into(), json!(vf.diagnostics));
        if let Some(b) = &vf.before_enclosure {
            extra.insert("diagnostics_before_enclosure".into(), json!(b));
        }
        if let Some(e) = &vf.enclosure {
            extra.insert("enclosure".into(), json!(e));
        }
        extra.insert("form_factors".into(), json!(vf.stats));
        if let Some(c) = &comparison {
            extra.insert("comparison".into(), c.clone());
        }
        let exchange = if emittances {
            Some(radiosity::thermal::total_exchange_factors(vf.matrix.as_slice(), &emissivity)?)
        } else {
            None
        };
        if let Some((sf, t)) = sparse {
            let n = vf.matrix.n();
            let mut tr = Truncation::new(&areas, t)?;
            for i in 0..n {
                match &exchange {
                    Some(x) => tr.push(&x[i * n..(i + 1) * n]),
                    None => tr.push(vf.matrix.row(i)),
                }
            }
            write_truncated(a, sf, tr, &meta, &mut extra)?;
        } else {
        write_atomic_stream(&a.output, |file| {
            let mut mw = MatrixWriter::begin(format, file, &meta)?;
            for i in 0..vf.matrix.n() {
                match &exchange {
                    Some(x) => mw.row(&x[i * vf.matrix.n()..(i + 1) * vf.matrix.n()])?,
                    None => mw.row(vf.matrix.row(i))?,
                }
            }
            mw.finish(&extra)?;
            Ok(())
        })?;
        }
        if let (Some(e), false) = (&vf.enclosure, a.quiet) {
            eprintln!(
                "enclosure correction: {} iterations; closure error {:.2e} → {:.2e}, reciprocity {:.2e} → {:.2e}; \
                 largest change of a factor {:.2e} (relative {:.2e})",
                e.iterations,
                e.closure_error_before,
                e.closure_error_after,
                e.reciprocity_rel_before,
                e.reciprocity_rel_after,
                e.max_change,
                e.relative_change
            );
        }
        (vf.diagnostics, vf.stats, comparison)
    };
    let seconds = t1.elapsed().as_secs_f64();
    if !a.quiet {
        summarize(&diagnostics, seconds, &stats);
        if let Some(c) = &comparison {
            eprintln!(
                "against {}: max |ΔF| = {:.3e} at [{}][{}]",
                a.compare.as_ref().map(|p| p.display().to_string()).unwrap_or_default(),
                c["max_abs_error"].as_f64().unwrap_or(f64::NAN),
                c["worst"][0].as_str().unwrap_or("?"),
                c["worst"][1].as_str().unwrap_or("?")
            );
        }
    }
    if let Some(p) = &a.report {
        let report = json!({
            "version": env!("CARGO_PKG_VERSION"),
            "scene": a.scene,
            "method": method.name(),
            "per": per.name(),
            "rows": job.len(),
            "surfaces_computed": job.elements(),
            "streamed": stream,
            "seconds_form_factors": seconds,
            "seconds_total": t0.elapsed().as_secs_f64(),
            "threads": rayon::current_num_threads(),
            "diagnostics": diagnostics,
            "form_factors": stats,
            "comparison": comparison,
            "output": a.output.display().to_string(),
        });
        crate::common::write_atomic(p, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(ExitCode::SUCCESS)
}

fn summarize(d: &Diagnostics, seconds: f64, stats: &form_factor::Stats) {
    let rec = match (d.reciprocity_max_abs, d.reciprocity_max_rel) {
        (Some(a), Some(r)) => format!("reciprocity max |AᵢFᵢⱼ − AⱼFⱼᵢ| = {a:.3e} (relative {r:.3e})"),
        _ => "reciprocity not checked (streamed)".into(),
    };
    eprintln!(
        "{:.2} s, {} rays; row sums {:.6} … {:.6} (closure error {:.3e}); {rec}; {} negative, {} above 1",
        seconds, stats.rays, d.row_sum_min, d.row_sum_max, d.closure_max_error, d.negative_entries, d.entries_above_one
    );
}

/// Writes a file through `f` into a temporary file beside it, then renames it into place
/// (so a failed or interrupted run leaves no half-written file; see
/// [`crate::common::write_atomic_with`]).
fn write_atomic_stream(path: &Path, f: impl FnOnce(BufWriter<File>) -> Result<()>) -> Result<()> {
    crate::common::write_atomic_with(path, f)
}

/// `8G`, `512M`, `1.5GiB`, `100000` (bytes).
pub(crate) fn parse_size(s: &str) -> Result<u64> {
    let t = s.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num.trim().parse().with_context(|| format!("--memory-limit: '{s}' is not a size"))?;
    let mul = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" | "kib" => 1024.0,
        "m" | "mb" | "mib" => 1024.0 * 1024.0,
        "g" | "gb" | "gib" => 1024.0 * 1024.0 * 1024.0,
        "t" | "tb" | "tib" => 1024f64.powi(4),
        u => bail!("--memory-limit: unknown unit '{u}' (use K, M, G or T)"),
    };
    if !(v.is_finite() && v > 0.0) {
        bail!("--memory-limit must be positive, got '{s}'");
    }
    Ok((v * mul) as u64)
}

/// Largest absolute difference from a reference matrix, matched by names when all the
/// reference's names are ours, else by position.
fn compare(path: &Path, names: &[String], m: &radiosity::transport::DenseMatrix) -> Result<Value> {
    // Regular files only, with the library's size cap (not /dev/zero until memory runs out).
    let bytes = radiosity::scene::read_input(path).with_context(|| format!("cannot read {}", path.display()))?;
    let v: Value = serde_json::from_slice(&bytes).with_context(|| format!("{}: not JSON", path.display()))?;
    let rnames: Vec<String> = v
        .get("names")
        .or_else(|| v.get("faces"))
        .and_then(Value::as_array)
        .with_context(|| format!("{}: no 'names' (or 'faces') array", path.display()))?
        .iter()
        .map(|x| x.as_str().unwrap_or("").to_string())
        .collect();
    let rows = v
        .get("matrix")
        .or_else(|| v.get("F_i_to_j"))
        .and_then(Value::as_array)
        .with_context(|| format!("{}: no 'matrix' (or 'F_i_to_j') array", path.display()))?;
    let idx: Vec<usize> = if rnames.iter().all(|r| names.contains(r)) {
        rnames.iter().map(|r| names.iter().position(|n| n == r).unwrap_or(0)).collect()
    } else if rnames.len() == names.len() {
        (0..names.len()).collect()
    } else {
        bail!("{}: its {} surfaces do not match ours ({})", path.display(), rnames.len(), names.len());
    };
    let (mut worst, mut at, mut row_worst) = (0.0f64, (0, 0), vec![0.0f64; idx.len()]);
    for (a, row) in rows.iter().enumerate() {
        let row = row.as_array().with_context(|| format!("{}: row {a} is not an array", path.display()))?;
        for (b, x) in row.iter().enumerate() {
            let r = x.as_f64().with_context(|| format!("{}: [{a}][{b}] is not a number", path.display()))?;
            let e = (m.get(idx[a], idx[b]) - r).abs();
            row_worst[a] = row_worst[a].max(e);
            if e > worst {
                worst = e;
                at = (a, b);
            }
        }
    }
    let per_row: Map<String, Value> = rnames.iter().zip(&row_worst).map(|(n, e)| (n.clone(), json!(e))).collect();
    Ok(json!({
        "reference": path.display().to_string(),
        "max_abs_error": worst,
        "worst": [rnames[at.0], rnames[at.1]],
        "max_abs_error_per_row": per_row,
    }))
}

/// Rebalances the collected rows and writes the sparse matrix, with the report in `extra`.
fn write_truncated(
    a: &ViewfactorsArgs,
    format: SparseFormat,
    tr: Truncation,
    meta: &MatrixMeta,
    extra: &mut Map<String, serde_json::Value>,
) -> Result<()> {
    let (m, rep) = tr.finish()?;
    if !a.quiet {
        eprintln!(
            "sparse: {} of {} non-zero entries kept (threshold {:e}, density {:.2e}); up to {:.2e} of a row's sum \
             given back to its kept entries; row sums kept to {:.1e}, reciprocity {:.1e}; largest change of a kept \
             factor {:.2e}{}",
            rep.kept,
            rep.nonzero_before,
            rep.threshold,
            rep.density,
            rep.max_dropped_row_share,
            rep.row_sum_error,
            rep.reciprocity_rel,
            rep.max_change,
            if rep.emptied_rows > 0 { format!("; {} rows lost every entry", rep.emptied_rows) } else { String::new() }
        );
    }
    extra.insert("sparse".into(), json!(rep));
    write_atomic_stream(&a.output, |file| {
        write_sparse(format, file, meta, &m, extra)?;
        Ok(())
    })?;
    Ok(())
}
