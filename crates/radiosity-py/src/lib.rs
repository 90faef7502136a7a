//! Python bindings of the `radiosity` library (pyo3 + rust-numpy, built by maturin).
//!
//! NumPy arrays in, NumPy arrays out: vertices `(nv, 3)` float, faces `(nf, k)` integer or a
//! list of index lists; matrices come back as `(n, n)` float64 arrays that own the Rust
//! buffer (no copy). The GIL is released while the work runs on all cores; Ctrl-C
//! (KeyboardInterrupt) stops it within a fraction of a second.

use std::sync::Mutex;
use std::time::Duration;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use radiosity_core as rc;
use rc::scene::arrays::{scene_from_arrays, Arrays};
use rc::scene::{Boundary, SceneDesc, ThermalDesc};
use rc::view_factors::{Per, Settings as VfSettings};
use rc::{Progress, Rgb};

fn to_py(e: rc::Error) -> PyErr {
    match e {
        rc::Error::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// Runs `work` with the GIL released, on another thread, while this one watches for
/// signals (Python runs signal handlers on the main thread only): a KeyboardInterrupt
/// stops the work and is raised.
fn run<T: Send>(py: Python<'_>, work: impl FnOnce(&dyn Progress) -> rc::Result<T> + Send) -> PyResult<T> {
    let stop = rc::progress::StopFlag::default();
    let signal: Mutex<Option<PyErr>> = Mutex::new(None);
    let stop = &stop;
    let out = py.detach(|| {
        std::thread::scope(|s| {
            let (done, finished) = std::sync::mpsc::channel::<()>();
            let h = s.spawn(move || {
                let r = work(stop);
                let _ = done.send(());
                r
            });
            // Wake as soon as the work ends (no polling floor), else every 20 ms for signals.
            while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) = finished.recv_timeout(Duration::from_millis(20))
            {
                if let Err(e) = Python::attach(|py| py.check_signals()) {
                    stop.stop();
                    *signal.lock().unwrap() = Some(e);
                }
            }
            h.join()
        })
    });
    if let Some(e) = signal.into_inner().unwrap() {
        return Err(e);
    }
    match out {
        Ok(r) => r.map_err(to_py),
        Err(_) => Err(PyRuntimeError::new_err("the computation panicked (a bug: please report it)")),
    }
}

fn vertices_of(py: Python<'_>, v: &Bound<'_, PyAny>) -> PyResult<Vec<[f64; 3]>> {
    let np = py.import("numpy")?;
    let kw = PyDict::new(py);
    kw.set_item("dtype", "float64")?;
    let arr = np.call_method("ascontiguousarray", (v,), Some(&kw))?;
    let a: PyReadonlyArray2<f64> =
        arr.extract().map_err(|_| PyValueError::new_err("vertices must be an (n, 3) array of coordinates"))?;
    if a.shape()[1] != 3 {
        return Err(PyValueError::new_err(format!("vertices have shape {:?}; (n, 3) expected", a.shape())));
    }
    Ok(a.as_slice()?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

fn faces_of(py: Python<'_>, f: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<usize>>> {
    let np = py.import("numpy")?;
    let kw = PyDict::new(py);
    kw.set_item("dtype", "int64")?;
    let rows: Vec<Vec<i64>> = match np.call_method("ascontiguousarray", (f,), Some(&kw)) {
        Ok(arr) if arr.getattr("ndim")?.extract::<usize>()? == 2 => {
            let a: PyReadonlyArray2<i64> = arr.extract()?;
            let k = a.shape()[1];
            a.as_slice()?.chunks_exact(k.max(1)).map(|c| c.to_vec()).collect()
        }
        // Ragged: a list of index lists (polygons of different sizes).
        _ => f.extract().map_err(|_| {
            PyValueError::new_err("faces must be an (n, k) integer array or a list of vertex-index lists")
        })?,
    };
    rows.into_iter()
        .enumerate()
        .map(|(k, r)| {
            r.into_iter()
                .map(|i| {
                    usize::try_from(i)
                        .map_err(|_| PyValueError::new_err(format!("face {k}: negative vertex index {i}")))
                })
                .collect()
        })
        .collect()
}

fn int_list(py: Python<'_>, x: Option<&Bound<'_, PyAny>>, what: &str) -> PyResult<Vec<i64>> {
    let Some(x) = x else { return Ok(Vec::new()) };
    let np = py.import("numpy")?;
    let a = np.call_method1("ravel", (np.call_method1("asarray", (x,))?,))?;
    a.call_method1("astype", ("int64",))
        .and_then(|a| Ok(a.extract::<PyReadonlyArray1<i64>>()?.as_slice()?.to_vec()))
        .map_err(|_| PyValueError::new_err(format!("{what} must be a sequence of integers")))
}

/// Obstructions: a boolean mask over the faces or a list of face indices.
fn obstruction_mask(py: Python<'_>, x: Option<&Bound<'_, PyAny>>, nf: usize) -> PyResult<Vec<bool>> {
    let Some(x) = x else { return Ok(Vec::new()) };
    let np = py.import("numpy")?;
    let a = np.call_method1("asarray", (x,))?;
    if a.getattr("dtype")?.getattr("kind")?.extract::<String>()? == "b" {
        let m: Vec<bool> = a.call_method0("tolist")?.extract()?;
        if m.len() != nf {
            return Err(PyValueError::new_err(format!("obstruction mask has {} entries for {nf} faces", m.len())));
        }
        return Ok(m);
    }
    let mut m = vec![false; nf];
    for i in int_list(py, Some(x), "obstructions")? {
        *usize::try_from(i).ok().and_then(|i| m.get_mut(i)).ok_or_else(|| {
            PyValueError::new_err(format!("obstruction index {i} is not a face (0 to {})", nf.saturating_sub(1)))
        })? = true;
    }
    Ok(m)
}

struct Geometry {
    desc: SceneDesc,
    /// Surface labels in row order.
    labels: Vec<i64>,
}

fn geometry(
    py: Python<'_>,
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
    surfaces: Option<&Bound<'_, PyAny>>,
    obstructions: Option<&Bound<'_, PyAny>>,
    two_sided: bool,
) -> PyResult<Geometry> {
    let v = vertices_of(py, vertices)?;
    let f = faces_of(py, faces)?;
    let labels = int_list(py, surfaces, "surfaces")?;
    let obstruction = obstruction_mask(py, obstructions, f.len())?;
    let (mut desc, labels) =
        scene_from_arrays(&Arrays { vertices: &v, faces: &f, labels: &labels, obstruction: &obstruction })
            .map_err(to_py)?;
    desc.two_sided = two_sided;
    Ok(Geometry { desc, labels })
}

fn form_factor_options(method: &str, seed: u64, tolerance: Option<f64>) -> PyResult<rc::form_factor::Options> {
    let mut o = rc::form_factor::Options {
        method: method.parse().map_err(|e: rc::Error| PyValueError::new_err(e.to_string()))?,
        seed,
        ..Default::default()
    };
    if let Some(t) = tolerance {
        o.adaptive_tolerance = t;
    }
    o.validate().map_err(to_py)?;
    Ok(o)
}

fn json_to_py<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let s = serde_json::to_string(v).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (s,))
}

/// Rows of the result in the order of `labels` (front, then back for two-sided), from the
/// names the library gives its rows; surfaces left without area (degenerate faces) are
/// rows of zeros.
fn row_order(labels: &[i64], two_sided: bool, names: &[String]) -> (Vec<Option<usize>>, Vec<String>) {
    let mut want: Vec<String> = Vec::new();
    for l in labels {
        want.push(l.to_string());
        if two_sided {
            want.push(format!("{l} (back)"));
        }
    }
    let at: std::collections::HashMap<&str, usize> = names.iter().enumerate().map(|(k, n)| (n.as_str(), k)).collect();
    (want.iter().map(|w| at.get(w.as_str()).copied()).collect(), want)
}

/// View factors between the faces of a mesh, with occlusion.
///
/// Parameters
/// ----------
/// vertices : (nv, 3) array of float
/// faces : (nf, k) integer array, or a list of vertex-index lists (planar polygons; the
///     front side by the right-hand rule, counter-clockwise seen from the front)
/// method : "adaptive" (default: error-controlled, occlusion by rays), "analytic" (exact,
///     ignores occlusion), "point-sampled", "monte-carlo", "hemicube"
/// surfaces : optional integer label per face; faces with one label form one surface
///     (one row), rows in increasing label order (default: one row per face)
/// obstructions : optional boolean mask or index list of faces that only block (no row)
/// two_sided : every face has two sides, each its own row (front 2k, back 2k + 1)
/// enclosure : enforce reciprocity and closure (closed geometry only)
/// mesh_size : element size for the integration (default: the faces themselves for the
///     area-to-area methods, else diagonal / 40)
/// tolerance : the adaptive method's relative tolerance
/// seed : seed of every random choice
///
/// Returns
/// -------
/// (F, areas, diagnostics): F[i, j] the fraction of the energy leaving surface i
/// (diffusely, from its front) that reaches surface j; areas (n,); diagnostics a dict
/// (row sums, reciprocity, enclosure correction, timings of the form factors).
#[pyfunction]
#[pyo3(signature = (vertices, faces, *, method="adaptive", surfaces=None, obstructions=None, two_sided=false,
    enclosure=false, mesh_size=None, tolerance=None, seed=0))]
#[allow(clippy::too_many_arguments)]
fn view_factors<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    method: &str,
    surfaces: Option<&Bound<'py, PyAny>>,
    obstructions: Option<&Bound<'py, PyAny>>,
    two_sided: bool,
    enclosure: bool,
    mesh_size: Option<f64>,
    tolerance: Option<f64>,
    seed: u64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let g = geometry(py, vertices, faces, surfaces, obstructions, two_sided)?;
    let ff = form_factor_options(method, seed, tolerance)?;
    let settings = VfSettings { per: Per::Object, mesh_size, form_factors: ff, enclosure };
    let desc = g.desc;
    let vf = run(py, move |p| {
        let scene = rc::scene::Scene::from_desc(desc)?;
        rc::view_factors::compute(scene, &settings, p)
    })?;
    let (rows, _) = row_order(&g.labels, two_sided, &vf.names);
    let diag = PyDict::new(py);
    diag.set_item("view_factors", json_to_py(py, &vf.diagnostics)?)?;
    diag.set_item("form_factors", json_to_py(py, &vf.stats)?)?;
    if let Some(e) = &vf.enclosure {
        diag.set_item("enclosure", json_to_py(py, e)?)?;
    }
    let missing: Vec<usize> = rows.iter().enumerate().filter(|(_, r)| r.is_none()).map(|(k, _)| k).collect();
    diag.set_item("empty_rows", missing.clone())?;
    let n = rows.len();
    let (matrix, areas) = if missing.is_empty() && rows.iter().enumerate().all(|(k, r)| *r == Some(k)) {
        (vf.matrix.into_vec(), vf.areas)
    } else {
        let mut m = vec![0.0; n * n];
        let mut a = vec![0.0; n];
        for (i, ri) in rows.iter().enumerate() {
            let Some(ri) = *ri else { continue };
            a[i] = vf.areas[ri];
            let row = vf.matrix.row(ri);
            for (j, rj) in rows.iter().enumerate() {
                if let Some(rj) = *rj {
                    m[i * n + j] = row[rj];
                }
            }
        }
        (m, a)
    };
    if !missing.is_empty() {
        let w = py.import("warnings")?;
        w.call_method1(
            "warn",
            (format!("{} surface(s) have no area (degenerate faces): rows of zeros", missing.len()),),
        )?;
    }
    let f = Array2::from_shape_vec((n, n), matrix).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok((f.into_pyarray(py).into_any(), areas.into_pyarray(py).into_any(), diag.into_any()))
}

/// Per-surface values: a scalar for all, or one per surface.
fn per_surface(py: Python<'_>, x: Option<&Bound<'_, PyAny>>, n: usize, what: &str) -> PyResult<Option<Vec<f64>>> {
    let Some(x) = x else { return Ok(None) };
    if let Ok(v) = x.extract::<f64>() {
        return Ok(Some(vec![v; n]));
    }
    let np = py.import("numpy")?;
    let a = np.call_method1("ravel", (np.call_method1("asarray", (x, "float64"))?,))?;
    let v: Vec<f64> = a.extract::<PyReadonlyArray1<f64>>()?.as_slice()?.to_vec();
    if v.len() != n {
        return Err(PyValueError::new_err(format!("{what}: {} values for {n} surfaces", v.len())));
    }
    Ok(Some(v))
}

fn thermal_geometry(
    py: Python<'_>,
    g: &mut Geometry,
    emissivity: &Bound<'_, PyAny>,
    boundary: Option<(&Option<Vec<f64>>, &Option<Vec<f64>>, &Option<Vec<bool>>)>,
) -> PyResult<()> {
    let n = g.labels.len();
    // A 2-D array: one row of band emissivities per surface.
    let np = py.import("numpy")?;
    let arr = np.call_method1("asarray", (emissivity, "float64"))?;
    let bands: Option<Vec<Vec<f64>>> = if arr.getattr("ndim")?.extract::<usize>()? == 2 {
        let rows: Vec<Vec<f64>> = arr.call_method0("tolist")?.extract()?;
        if rows.len() != n {
            return Err(PyValueError::new_err(format!("emissivity: {} rows of band values for {n} surfaces", rows.len())));
        }
        Some(rows)
    } else {
        None
    };
    let eps = match &bands {
        Some(rows) => rows.iter().map(|r| r.iter().sum::<f64>() / r.len().max(1) as f64).collect(),
        None => per_surface(py, Some(emissivity), n, "emissivity")?.unwrap_or_default(),
    };
    for (k, e) in eps.iter().enumerate() {
        let all: Vec<f64> = bands.as_ref().map_or_else(|| vec![*e], |b| b[k].clone());
        if let Some(e) = all.iter().find(|e| !(**e > 0.0 && **e <= 1.0)) {
            return Err(PyValueError::new_err(format!("emissivity {e} of surface {} is not in (0, 1]", g.labels[k])));
        }
        let m = &mut g.desc.materials[k];
        m.reflectance = Rgb::splat(1.0 - e);
        let b = match boundary {
            None => None,
            Some((t, q, ad)) => {
                let t = t.as_ref().map(|v| v[k]).filter(|x| !x.is_nan());
                let q = q.as_ref().map(|v| v[k]).filter(|x| !x.is_nan());
                let ad = ad.as_ref().is_some_and(|v| v[k]);
                Some(match (t, q, ad) {
                    (Some(t), None, false) => Boundary::Temperature(t),
                    (None, Some(q), false) => Boundary::HeatFlux(q),
                    (None, None, true) => Boundary::Adiabatic,
                    (None, None, false) => {
                        return Err(PyValueError::new_err(format!(
                            "surface {}: no boundary condition (give temperature, heat_flux or adiabatic)",
                            g.labels[k]
                        )))
                    }
                    _ => {
                        return Err(PyValueError::new_err(format!(
                            "surface {}: more than one boundary condition (temperature, heat_flux, adiabatic)",
                            g.labels[k]
                        )))
                    }
                })
            }
        };
        let band_emissivity = bands.as_ref().map(|b| b[k].clone()).unwrap_or_default();
        m.thermal = Some(ThermalDesc { emissivity: Some(*e), boundary: b, band_emissivity });
    }
    Ok(())
}

fn thermal_settings(
    method: &str,
    mesh_size: Option<f64>,
    enclosure: bool,
    environment: f64,
    seed: u64,
    band_edges: Option<Vec<f64>>,
) -> PyResult<rc::thermal::Settings> {
    Ok(rc::thermal::Settings {
        view_factors: VfSettings {
            per: Per::Element,
            mesh_size,
            form_factors: form_factor_options(method, seed, None)?,
            enclosure,
        },
        environment,
        band_edges,
    })
}

/// Grey-body radiative exchange between the surfaces of a mesh (net-radiation method).
///
/// Every surface needs one boundary condition: a temperature [K], a net heat flux
/// [W/m², leaving] or adiabatic (re-radiating). Give them per surface as arrays with NaN
/// (or False) where a surface takes another kind, or as scalars for all.
///
/// Parameters
/// ----------
/// vertices, faces, surfaces, obstructions, two_sided : as for `view_factors`
/// emissivity : scalar or per surface, in (0, 1]; with `band_edges`, an array of shape
///     (surfaces, bands) gives each surface one emissivity per band
/// temperature, heat_flux : scalar or per surface (NaN: not given)
/// adiabatic : bool or per surface
/// environment : temperature [K] of what the geometry does not close (1 − Σ F)
/// method : form factors per element (default "point-sampled")
/// mesh_size : element size (default: diagonal / 40; 0: the faces themselves)
/// enclosure : enforce reciprocity and closure (closed geometry only)
/// band_edges : wavelengths in µm that split the spectrum into bands (band-energy
///     approximation: each band a grey exchange of its share of the blackbody emission)
///
/// Returns
/// -------
/// dict: "area", "emissivity" (with bands: total, at each surface's temperature),
/// "temperature", "heat_flux" (W/m², leaving), "heat" (W), "radiosity", "irradiance" (per
/// surface arrays), with bands "band_heat" (surfaces, bands) in W, "environment_heat",
/// "balance" (ΣQ − Q_env), "total" (Σ|Q|), "elements", "diagnostics".
#[pyfunction]
#[pyo3(signature = (vertices, faces, emissivity, *, temperature=None, heat_flux=None, adiabatic=None,
    environment=0.0, surfaces=None, obstructions=None, two_sided=false, method="point-sampled", mesh_size=None,
    enclosure=false, seed=0, band_edges=None))]
#[allow(clippy::too_many_arguments)]
fn exchange<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    emissivity: &Bound<'py, PyAny>,
    temperature: Option<&Bound<'py, PyAny>>,
    heat_flux: Option<&Bound<'py, PyAny>>,
    adiabatic: Option<&Bound<'py, PyAny>>,
    environment: f64,
    surfaces: Option<&Bound<'py, PyAny>>,
    obstructions: Option<&Bound<'py, PyAny>>,
    two_sided: bool,
    method: &str,
    mesh_size: Option<f64>,
    enclosure: bool,
    seed: u64,
    band_edges: Option<Vec<f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let mut g = geometry(py, vertices, faces, surfaces, obstructions, two_sided)?;
    let n = g.labels.len();
    let t = per_surface(py, temperature, n, "temperature")?;
    let q = per_surface(py, heat_flux, n, "heat_flux")?;
    let ad: Option<Vec<bool>> = match adiabatic {
        None => None,
        Some(x) => Some(match x.extract::<bool>() {
            Ok(b) => vec![b; n],
            Err(_) => {
                let v: Vec<bool> =
                    py.import("numpy")?.call_method1("asarray", (x, "bool"))?.call_method0("tolist")?.extract()?;
                if v.len() != n {
                    return Err(PyValueError::new_err(format!("adiabatic: {} values for {n} surfaces", v.len())));
                }
                v
            }
        }),
    };
    thermal_geometry(py, &mut g, emissivity, Some((&t, &q, &ad)))?;
    let settings = thermal_settings(method, mesh_size, enclosure, environment, seed, band_edges)?;
    let desc = g.desc;
    let th = run(py, move |p| rc::thermal::solve(rc::scene::Scene::from_desc(desc)?, &settings, p))?;
    let (rows, _) = row_order(&g.labels, two_sided, &th.surfaces.iter().map(|s| s.name.clone()).collect::<Vec<_>>());
    let d = PyDict::new(py);
    let col = |f: &dyn Fn(&rc::thermal::SurfaceResult) -> f64| -> Vec<f64> {
        rows.iter().map(|r| r.map_or(f64::NAN, |r| f(&th.surfaces[r]))).collect()
    };
    d.set_item("area", col(&|s| s.area).into_pyarray(py))?;
    d.set_item("emissivity", col(&|s| s.emissivity).into_pyarray(py))?;
    d.set_item("temperature", col(&|s| s.temperature).into_pyarray(py))?;
    d.set_item("heat_flux", col(&|s| s.heat_flux).into_pyarray(py))?;
    d.set_item("heat", col(&|s| s.heat).into_pyarray(py))?;
    d.set_item("radiosity", col(&|s| s.radiosity).into_pyarray(py))?;
    d.set_item("irradiance", col(&|s| s.irradiance).into_pyarray(py))?;
    if !th.band_edges.is_empty() {
        let nb = th.band_edges.len() + 1;
        let rows_b: Vec<Vec<f64>> =
            rows.iter().map(|r| r.map_or(vec![f64::NAN; nb], |r| th.surfaces[r].band_heat.clone())).collect();
        d.set_item("band_heat", numpy::PyArray2::from_vec2(py, &rows_b)?)?;
        d.set_item("band_edges", th.band_edges.clone())?;
    }
    d.set_item("environment_heat", th.environment_heat)?;
    d.set_item("balance", th.balance)?;
    d.set_item("total", th.total)?;
    d.set_item("elements", th.elements)?;
    d.set_item("diagnostics", json_to_py(py, &th.diagnostics)?)?;
    Ok(d)
}

/// Gebhart factors and radiative conductances between the surfaces of a mesh.
///
/// B[i, j] is the share of surface i's emission that surface j absorbs after any number of
/// diffuse reflections; GR[i, j] = ε_i A_i B[i, j] (Q_ij = σ GR_ij (T_i⁴ − T_j⁴)); the
/// script-F of Hottel (View3D's emittance-weighted factors) is ε_i B[i, j].
///
/// Returns a dict: "gebhart" (n, n), "conductance" (n, n), "to_environment" (n,), "area",
/// "emissivity", "reciprocity" (largest relative asymmetry of GR).
#[pyfunction]
#[pyo3(signature = (vertices, faces, emissivity, *, surfaces=None, obstructions=None, two_sided=false,
    method="point-sampled", mesh_size=None, enclosure=false, seed=0))]
#[allow(clippy::too_many_arguments)]
fn exchange_factors<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    emissivity: &Bound<'py, PyAny>,
    surfaces: Option<&Bound<'py, PyAny>>,
    obstructions: Option<&Bound<'py, PyAny>>,
    two_sided: bool,
    method: &str,
    mesh_size: Option<f64>,
    enclosure: bool,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let mut g = geometry(py, vertices, faces, surfaces, obstructions, two_sided)?;
    thermal_geometry(py, &mut g, emissivity, None)?;
    let settings = thermal_settings(method, mesh_size, enclosure, 0.0, seed, None)?;
    let desc = g.desc;
    let x = run(py, move |p| rc::thermal::exchange_factors(rc::scene::Scene::from_desc(desc)?, &settings, p))?;
    let (rows, _) = row_order(&g.labels, two_sided, &x.names);
    let n = rows.len();
    let ns = x.names.len();
    let pick = |m: &[f64]| -> PyResult<Array2<f64>> {
        let mut out = vec![0.0; n * n];
        for (i, ri) in rows.iter().enumerate() {
            for (j, rj) in rows.iter().enumerate() {
                if let (Some(a), Some(b)) = (ri, rj) {
                    out[i * n + j] = m[a * ns + b];
                }
            }
        }
        Array2::from_shape_vec((n, n), out).map_err(|e| PyRuntimeError::new_err(e.to_string()))
    };
    let vec = |v: &[f64]| -> Vec<f64> { rows.iter().map(|r| r.map_or(0.0, |r| v[r])).collect() };
    let d = PyDict::new(py);
    d.set_item("gebhart", pick(&x.gebhart)?.into_pyarray(py))?;
    d.set_item("conductance", pick(&x.conductance)?.into_pyarray(py))?;
    d.set_item("to_environment", vec(&x.to_environment).into_pyarray(py))?;
    d.set_item("area", vec(&x.areas).into_pyarray(py))?;
    d.set_item("emissivity", vec(&x.emissivity).into_pyarray(py))?;
    d.set_item("reciprocity", x.reciprocity)?;
    d.set_item("elements", x.elements)?;
    Ok(d)
}

/// A scene read from a file (.obj, .gltf/.glb, .toml, .vs3) or a built-in name
/// ("cornell", "furnace").
#[pyclass(module = "radiosity", frozen)]
struct Scene {
    desc: SceneDesc,
    source: String,
}

#[pymethods]
impl Scene {
    /// Object names, in the order results are given.
    #[getter]
    fn objects(&self) -> Vec<String> {
        self.desc.objects.iter().map(|o| o.name.clone()).collect()
    }
    /// Number of input polygons.
    #[getter]
    fn polygons(&self) -> usize {
        self.desc.polygons.len()
    }
    /// The geometry as arrays, for `view_factors`, `exchange` and `exchange_factors`:
    /// (vertices (nv, 3), faces (list of index lists), surfaces (nf,) object index per face,
    /// obstructions (nf,) bool).
    fn arrays<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
        let mut v: Vec<f64> = Vec::new();
        let mut faces: Vec<Vec<usize>> = Vec::new();
        for p in &self.desc.polygons {
            let first = v.len() / 3;
            faces.push((first..first + p.vertices.len()).collect());
            v.extend(p.vertices.iter().flat_map(|x| x.to_array()));
        }
        let n = v.len() / 3;
        let vertices = Array2::from_shape_vec((n, 3), v).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        let surfaces: Vec<i64> = self.desc.polygons.iter().map(|p| p.object as i64).collect();
        let blocks: Vec<bool> = self.desc.polygons.iter().map(|p| self.desc.obstructions.contains(&p.object)).collect();
        pyo3::types::PyTuple::new(
            py,
            [
                vertices.into_pyarray(py).into_any(),
                PyList::new(py, faces)?.into_any(),
                surfaces.into_pyarray(py).into_any(),
                blocks.into_pyarray(py).into_any(),
            ],
        )
    }
    fn __repr__(&self) -> String {
        format!("Scene('{}': {} objects, {} polygons)", self.source, self.desc.objects.len(), self.desc.polygons.len())
    }
}

/// Reads a scene file (or a built-in name) into a `Scene`.
#[pyfunction]
fn load_scene(py: Python<'_>, path: String) -> PyResult<Scene> {
    if !rc::scene::builtin::NAMES.contains(&path.as_str()) && !std::path::Path::new(&path).exists() {
        return Err(pyo3::exceptions::PyFileNotFoundError::new_err(format!(
            "{path}: no such file (built-in scenes: {})",
            rc::scene::builtin::NAMES.join(", ")
        )));
    }
    let p = path.clone();
    let desc = run(py, move |_| rc::scene::load(&p))?;
    Ok(Scene { desc, source: path })
}

/// Solves the radiosity equation B = E + ρFB of a scene and returns the radiosity per
/// object.
///
/// Parameters
/// ----------
/// scene : a `Scene` from `load_scene`
/// solver : "chebyshev" (default), "jacobi", "gauss-seidel", "shooting", "progressive",
///     "direct", "stochastic-jacobi", "stochastic-shooting"
/// method : form factors ("point-sampled" default, "hemicube", "monte-carlo", "analytic",
///     "adaptive")
/// mesh_size : element size (default: diagonal / 40)
/// two_sided : every surface has two sides
/// tolerance, max_iterations : the solver's stopping rule
///
/// Returns
/// -------
/// dict: "names", "area" (n,), "radiosity" (n, 3) and "radiance" (n, 3) area means of the
/// front side (linear RGB, W/m² and W/(m² sr) for a scene in metres with Ke in
/// W/(m² sr)), "report" (the full JSON report of `radiosity render`, as a dict).
#[pyfunction]
#[pyo3(signature = (scene, *, solver="chebyshev", method="point-sampled", mesh_size=None, two_sided=false,
    tolerance=None, max_iterations=None, seed=0))]
#[allow(clippy::too_many_arguments)]
fn solve<'py>(
    py: Python<'py>,
    scene: &Scene,
    solver: &str,
    method: &str,
    mesh_size: Option<f64>,
    two_sided: bool,
    tolerance: Option<f64>,
    max_iterations: Option<usize>,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let mut settings = rc::pipeline::Settings {
        mesh_size,
        form_factors: form_factor_options(method, seed, None)?,
        solver: solver.parse().map_err(|e: rc::Error| PyValueError::new_err(e.to_string()))?,
        ..Default::default()
    };
    if let Some(t) = tolerance {
        if !(t > 0.0) {
            return Err(PyValueError::new_err(format!("tolerance {t} must be positive")));
        }
        settings.solve.tolerance = t;
    }
    if let Some(m) = max_iterations {
        settings.solve.max_iterations = m;
    }
    settings.solve.seed = seed;
    let mut desc = scene.desc.clone();
    desc.two_sided |= two_sided;
    let (objects, report) = run(py, move |p| {
        let s = rc::pipeline::solve_scene(rc::scene::Scene::from_desc(desc)?, &settings, p)?;
        Ok((s.objects(), s.report()))
    })?;
    let d = PyDict::new(py);
    d.set_item("names", PyList::new(py, objects.iter().map(|o| o.name.clone()))?)?;
    d.set_item("area", objects.iter().map(|o| o.area).collect::<Vec<_>>().into_pyarray(py))?;
    let rgb = |f: &dyn Fn(&rc::report::ObjectReport) -> [f64; 3]| -> PyResult<Array2<f64>> {
        Array2::from_shape_vec((objects.len(), 3), objects.iter().flat_map(f).collect())
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))
    };
    d.set_item("radiosity", rgb(&|o| o.radiosity_rgb)?.into_pyarray(py))?;
    d.set_item("radiance", rgb(&|o| o.radiance_rgb)?.into_pyarray(py))?;
    d.set_item("report", json_to_py(py, &report)?)?;
    Ok(d)
}

/// View factors with occlusion, grey-body radiative exchange and radiosity, from NumPy
/// arrays or scene files (the `radiosity` engine's Python interface).
#[pymodule]
fn radiosity(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("STEFAN_BOLTZMANN", rc::thermal::STEFAN_BOLTZMANN)?;
    m.add_function(wrap_pyfunction!(view_factors, m)?)?;
    m.add_function(wrap_pyfunction!(exchange, m)?)?;
    m.add_function(wrap_pyfunction!(exchange_factors, m)?)?;
    m.add_function(wrap_pyfunction!(load_scene, m)?)?;
    m.add_function(wrap_pyfunction!(solve, m)?)?;
    m.add_class::<Scene>()?;
    Ok(())
}
