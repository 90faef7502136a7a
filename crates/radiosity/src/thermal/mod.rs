//! Radiative heat transfer between grey, diffuse, opaque surfaces: the net-radiation method
//! (Hottel & Sarofim 1967; Modest, *Radiative Heat Transfer*, ch. 5) on our view factors.
//!
//! Every element `i` of a surface with emissivity `εᵢ` leaves with radiosity
//! `Jᵢ = εᵢσTᵢ⁴ + (1 − εᵢ)Gᵢ` and receives the irradiance
//! `Gᵢ = Σⱼ Fᵢⱼ Jⱼ + Fᵢ,env σT_env⁴`, where `Fᵢ,env = 1 − Σⱼ Fᵢⱼ` is what leaves the
//! geometry (an environment — the sky, deep space, a hall — at `T_env` takes the rest of each
//! row; 0 for a closed enclosure). Its net radiative flux is `qᵢ = Jᵢ − Gᵢ` (W/m², positive
//! when the surface loses heat). A boundary condition per surface closes the system:
//!
//! - temperature `T`: `Jᵢ − (1 − εᵢ) Σⱼ Fᵢⱼ Jⱼ = εᵢσTᵢ⁴ + (1 − εᵢ)Fᵢ,env σT_env⁴`;
//! - net heat flux `q` (W/m², uniform over the surface): `Jᵢ − Σⱼ Fᵢⱼ Jⱼ = q + Fᵢ,env σT_env⁴`,
//!   and afterwards `σTᵢ⁴ = (Jᵢ − (1 − εᵢ)Gᵢ)/εᵢ`;
//! - adiabatic (re-radiating): `q = 0`;
//! - a two-sided adiabatic material is a radiation shield, a thin conducting sheet: at
//!   each point its two sides share one temperature and the heat one absorbs the other
//!   emits, `Jf − (1 − ε)Gf = Jb − (1 − ε)Gb` and `(Jf − Gf) + (Jb − Gb) = 0`.
//!
//! The system (one unknown `J` per element, dense) is solved by LU factorisation. Results
//! are reported per input object (surface): area, ε, T (for flux surfaces the
//! area-weighted mean of T⁴, to the ¼), q = Q/A, Q = Σ qᵢAᵢ, and the area means of J and G;
//! the balance ΣQ − Q_env is zero for reciprocal view factors (exactly, to rounding, with
//! the enclosure correction of a closed geometry, `--enclosure`).
//!
//! Units: SI — temperatures in kelvin, lengths in metres (a scene in other units gives
//! fluxes per its unit²: scale Q accordingly).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve as lu_solve};
use faer::{Mat, Par};

use crate::form_factor::diagnostics::Diagnostics;
use crate::form_factor::enclosure::EnclosureReport;
use crate::scene::{Boundary, Scene, SceneDesc, ThermalDesc, ThermalSpec};
use crate::view_factors::{Job, Per, Settings as VfSettings};
use crate::{Error, Progress, Result};

pub mod bands;
pub mod viewht;

/// The Stefan–Boltzmann constant σ, W/(m²·K⁴) (CODATA 2018, exact in the SI).
pub const STEFAN_BOLTZMANN: f64 = 5.670_374_419e-8;

/// Most elements of the dense system (its LU factorisation takes `n³/3` operations).
pub const MAX_ELEMENTS: usize = 20_000;

/// What decides a thermal solution.
#[derive(Clone, Debug)]
pub struct Settings {
    /// View factors (their `per` is ignored: the system is solved per element).
    pub view_factors: VfSettings,
    /// Temperature of the environment that takes the rest of each row, kelvin.
    pub environment: f64,
    /// Wavelengths (µm) that split the spectrum into bands for per-band emissivities
    /// (None: the scene's own, [`Scene::band_edges`]; empty: grey).
    pub band_edges: Option<Vec<f64>>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings { view_factors: VfSettings { per: Per::Element, ..Default::default() }, environment: 0.0, band_edges: None }
    }
}

/// One surface's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SurfaceResult {
    /// Object name (`name (back)` for the back side of a two-sided surface).
    pub name: String,
    /// What was given: "temperature", "heat flux", "adiabatic" or "shield" (a two-sided
    /// adiabatic sheet: both sides at one temperature, what one absorbs the other emits).
    pub boundary: &'static str,
    /// Area, scene units².
    pub area: f64,
    /// Emissivity (area mean over the surface's elements; with bands the total hemispherical
    /// emissivity Σ_b ε_b f_b(T) at each element's temperature).
    pub emissivity: f64,
    /// Temperature, K (given, or solved for flux and adiabatic surfaces).
    pub temperature: f64,
    /// Net radiative heat flux leaving, W per unit area (Q/A).
    pub heat_flux: f64,
    /// Net radiative heat leaving, W.
    pub heat: f64,
    /// Area-mean radiosity J, W per unit area.
    pub radiosity: f64,
    /// Area-mean irradiance G, W per unit area.
    pub irradiance: f64,
    /// With bands: the net heat leaving in each band, W (they sum to `heat`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub band_heat: Vec<f64>,
}

/// A solved enclosure.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Thermal {
    /// Per surface, in object order.
    pub surfaces: Vec<SurfaceResult>,
    /// Net heat the environment receives, W (zero for a closed geometry).
    pub environment_heat: f64,
    /// ΣQ − Q_env, W: zero when energy is conserved.
    pub balance: f64,
    /// Σ|Q| + |Q_env|, W: the scale of `balance`.
    pub total: f64,
    /// Elements of the system.
    pub elements: usize,
    /// The band edges the exchange was solved with, µm (empty: grey).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub band_edges: Vec<f64>,
    /// The view factors' diagnostics (row sums, reciprocity).
    #[serde(skip)]
    pub diagnostics: Diagnostics,
    /// The enclosure correction, when applied.
    #[serde(skip)]
    pub enclosure: Option<EnclosureReport>,
}

/// Solves the grey-body exchange of `scene`: every non-obstruction surface needs a
/// boundary condition ([`crate::scene::Material::thermal`]). With band edges
/// ([`Settings::band_edges`], else the scene's `[thermal] band_edges`) the exchange is
/// solved band by band (see [`bands`]).
pub fn solve(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<Thermal> {
    let sigma = STEFAN_BOLTZMANN;
    if !(settings.environment.is_finite() && settings.environment >= 0.0) {
        return Err(Error::Invalid(format!(
            "environment temperature {} K must be finite and ≥ 0",
            settings.environment
        )));
    }
    let edges = settings.band_edges.clone().unwrap_or_else(|| scene.band_edges.clone());
    bands::check_edges(&edges)?;
    // Every material used by a surface needs a boundary condition (and, with bands, one
    // emissivity per band or a grey one).
    let mut missing: Vec<String> = Vec::new();
    for p in &scene.polygons {
        let m = &scene.materials[p.material as usize];
        if scene.is_obstruction(p.object) {
            continue;
        }
        match &m.thermal {
            None if !missing.contains(&m.name) => missing.push(m.name.clone()),
            Some(t) if !t.band_emissivity.is_empty() && t.band_emissivity.len() != edges.len() + 1 => {
                return Err(bands::count_error(&m.name, t.band_emissivity.len(), &edges));
            }
            _ => {}
        }
    }
    if !missing.is_empty() {
        return Err(Error::Invalid(format!(
            "no thermal boundary condition for material(s) {}: give each a temperature, heat_flux or adiabatic = true \
             (TOML [materials.NAME])",
            missing.iter().map(|m| format!("'{m}'")).collect::<Vec<_>>().join(", ")
        )));
    }
    let vf = VfSettings { per: Per::Element, ..settings.view_factors.clone() };
    let job = Job::new(scene, vf)?;
    let n = job.len();
    if n > MAX_ELEMENTS {
        return Err(Error::Invalid(format!(
            "{n} elements: the dense thermal system holds at most {MAX_ELEMENTS}; raise --mesh-size"
        )));
    }
    let elements = job.output_elements();
    let vfs = job.compute(None, progress)?;
    let scene = job.scene();
    let mesh = job.mesh();
    let f = &vfs.matrix;
    let env = sigma * settings.environment.powi(4);
    // Per element: boundary condition, emissivity (grey), what leaves the geometry.
    let mut spec = Vec::with_capacity(n);
    let mut f_env = vec![0.0; n];
    for (r, &e) in elements.iter().enumerate() {
        let p = &scene.polygons[mesh.elements[e as usize].patch as usize];
        let m = &scene.materials[p.material as usize];
        spec.push(m.thermal.as_ref().ok_or_else(|| Error::Invalid("missing boundary condition".into()))?);
        let rowsum: f64 = f.row(r).iter().sum();
        f_env[r] = (1.0 - rowsum).max(0.0);
    }
    // Without a temperature anywhere, only the environment can fix the level of J.
    let any_t = spec.iter().any(|s| matches!(s.boundary, Boundary::Temperature(_)));
    let open: f64 = elements.iter().zip(&f_env).map(|(&e, fe)| mesh.elements[e as usize].area * fe).sum();
    let area: f64 = elements.iter().map(|&e| mesh.elements[e as usize].area).sum();
    if !any_t && open <= 1e-9 * area {
        return Err(Error::Invalid(
            "no surface has a temperature and the geometry is closed: with only heat-flux and adiabatic surfaces the \
             temperatures are undetermined; give at least one surface a temperature"
                .into(),
        ));
    }
    let pairs = shield_pairs(scene, mesh, &elements);
    let shield: Vec<bool> = {
        let mut v = vec![false; n];
        for &(x, y) in &pairs {
            v[x] = true;
            v[y] = true;
        }
        v
    };
    // Per element: total radiosity J, irradiance G, T⁴, emissivity (total, at T), and
    // with bands the net flux per band.
    let el = if edges.is_empty() {
        grey(f, &spec, &f_env, &pairs, env)?
    } else {
        if !pairs.is_empty() {
            return Err(Error::Invalid(
                "radiation shields (two-sided adiabatic materials) are solved grey only: leave out the band edges, or \
                 give the shield a heat flux"
                    .into(),
            ));
        }
        bands::solve(f, &spec, &f_env, &edges, settings.environment)?
    };
    // Per surface (object and side).
    let nb = el.band_q.first().map_or(0, |b| b.len());
    let mut order: Vec<(u32, bool)> = Vec::new();
    let mut acc: std::collections::HashMap<(u32, bool), ([f64; 7], Vec<f64>)> = std::collections::HashMap::new();
    let mut q_env = 0.0;
    for (r, &e) in elements.iter().enumerate() {
        let element = &mesh.elements[e as usize];
        let p = &scene.polygons[element.patch as usize];
        let (j, g) = (el.j[r], el.g[r]);
        let a = element.area;
        q_env += a * f_env[r] * (j - env);
        let key = (p.object, p.back_side);
        let (s, band) = acc.entry(key).or_insert_with(|| {
            order.push(key);
            ([0.0; 7], vec![0.0; nb])
        });
        s[0] += a;
        s[1] += a * el.eps[r];
        s[2] += a * el.t4[r];
        s[3] += a * (j - g);
        s[4] += a * j;
        s[5] += a * g;
        s[6] = match spec[r].boundary {
            Boundary::Temperature(_) => 0.0,
            Boundary::HeatFlux(_) => 1.0,
            _ if shield[r] => 3.0,
            _ => 2.0,
        };
        for (b, q) in band.iter_mut().zip(el.band_q.get(r).into_iter().flatten()) {
            *b += a * q;
        }
    }
    order.sort();
    let two_sided = scene.polygons.iter().any(|p| p.back_side);
    let surfaces: Vec<SurfaceResult> = order
        .iter()
        .map(|key| {
            let (s, band) = &acc[key];
            let name = &scene.objects[key.0 as usize].name;
            SurfaceResult {
                name: if two_sided && key.1 { format!("{name} (back)") } else { name.clone() },
                boundary: ["temperature", "heat flux", "adiabatic", "shield"][s[6] as usize],
                area: s[0],
                emissivity: s[1] / s[0],
                temperature: (s[2] / s[0]).powf(0.25),
                heat_flux: s[3] / s[0],
                heat: s[3],
                radiosity: s[4] / s[0],
                irradiance: s[5] / s[0],
                band_heat: band.clone(),
            }
        })
        .collect();
    let sum_q: f64 = surfaces.iter().map(|s| s.heat).sum();
    let total: f64 = surfaces.iter().map(|s| s.heat.abs()).sum::<f64>() + q_env.abs();
    Ok(Thermal {
        surfaces,
        environment_heat: q_env,
        balance: sum_q - q_env,
        total,
        elements: n,
        band_edges: edges,
        diagnostics: vfs.diagnostics,
        enclosure: vfs.enclosure,
    })
}

/// An element solution: total radiosity `J`, irradiance `G`, `T⁴`, the emissivity (with
/// bands: the total hemispherical emissivity at the element's temperature) and, with
/// bands, the net flux leaving in each band.
pub(crate) struct ElementSolution {
    pub j: Vec<f64>,
    pub g: Vec<f64>,
    pub t4: Vec<f64>,
    pub eps: Vec<f64>,
    pub band_q: Vec<Vec<f64>>,
}

/// The grey system: one unknown `J` per element, dense LU.
fn grey(f: &crate::transport::DenseMatrix, spec: &[&ThermalSpec], f_env: &[f64], pairs: &[(usize, usize)], env: f64) -> Result<ElementSolution> {
    let sigma = STEFAN_BOLTZMANN;
    let n = spec.len();
    if let Some(s) = spec.iter().find(|s| !s.band_emissivity.is_empty()) {
        return Err(Error::Invalid(format!(
            "a material gives {} band emissivities but the solve has no band edges: give [thermal] band_edges in the \
             scene or --bands",
            s.band_emissivity.len()
        )));
    }
    // Per element: emissivity, coefficient of Σ F J, right-hand side.
    let eps: Vec<f64> = spec.iter().map(|s| s.emissivity).collect();
    let mut coef = vec![0.0; n];
    let mut rhs = vec![0.0; n];
    for r in 0..n {
        match spec[r].boundary {
            Boundary::Temperature(t) => {
                coef[r] = 1.0 - eps[r];
                rhs[r] = eps[r] * sigma * t.powi(4) + (1.0 - eps[r]) * f_env[r] * env;
            }
            Boundary::HeatFlux(q) => {
                coef[r] = 1.0;
                rhs[r] = q + f_env[r] * env;
            }
            Boundary::Adiabatic => {
                coef[r] = 1.0;
                rhs[r] = f_env[r] * env;
            }
        }
    }
    // A J = b with A = I − diag(coef) F.
    let mut a = Mat::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } - coef[i] * f.get(i, j));
    // Shields: the two sides of a thin adiabatic sheet share a temperature and pass the heat
    // through, J_f − (1 − ε)G_f = J_b − (1 − ε)G_b and (J_f − G_f) + (J_b − G_b) = 0.
    for &(rf, rb) in pairs {
        let c = 1.0 - eps[rf];
        for k in 0..n {
            let (ff, fb) = (f.get(rf, k), f.get(rb, k));
            let d = |r: usize| if k == r { 1.0 } else { 0.0 };
            a[(rf, k)] = d(rf) - d(rb) - c * ff + c * fb;
            a[(rb, k)] = d(rf) + d(rb) - ff - fb;
        }
        rhs[rf] = c * (f_env[rf] - f_env[rb]) * env;
        rhs[rb] = (f_env[rf] + f_env[rb]) * env;
    }
    let mut x = Mat::<f64>::from_fn(n, 1, |i, _| rhs[i]);
    lu_solve_dense(a, &mut x);
    let j: Vec<f64> = (0..n).map(|i| x[(i, 0)]).collect();
    if j.iter().any(|v| !v.is_finite()) {
        return Err(singular());
    }
    let g: Vec<f64> = (0..n).map(|r| f.row(r).iter().zip(&j).map(|(fv, jv)| fv * jv).sum::<f64>() + f_env[r] * env).collect();
    let t4 = (0..n)
        .map(|r| match spec[r].boundary {
            Boundary::Temperature(t) => t.powi(4),
            _ if eps[r] > 0.0 => ((j[r] - (1.0 - eps[r]) * g[r]) / (eps[r] * sigma)).max(0.0),
            _ => f64::NAN,
        })
        .collect();
    Ok(ElementSolution { j, g, t4, eps, band_q: Vec::new() })
}

fn singular() -> Error {
    Error::Invalid(
        "the thermal system is singular: with only heat-flux and adiabatic surfaces in a closed enclosure the \
         temperatures are undetermined; give at least one surface a temperature"
            .into(),
    )
}

/// The objects that are surfaces of a thermal solve (every object but the obstructions),
/// in order: surface `k` (1-based, as in a ViewHT temperature file) is object
/// `surface_objects(desc)[k − 1]`.
pub fn surface_objects(desc: &SceneDesc) -> Vec<u32> {
    (0..desc.objects.len() as u32).filter(|o| !desc.obstructions.contains(o)).collect()
}

/// Gives surface `k` (see [`surface_objects`]) the temperature `t[k]` where it is `Some`:
/// its polygons get their own copy of their material with that boundary condition (the
/// emissivity kept).
pub fn set_temperatures(desc: &mut SceneDesc, t: &[Option<f64>]) -> Result<()> {
    let surfaces = surface_objects(desc);
    if t.len() > surfaces.len() {
        return Err(Error::Invalid(format!("{} temperatures for {} surfaces", t.len(), surfaces.len())));
    }
    let mut temperature = vec![None; desc.objects.len()];
    for (k, v) in t.iter().enumerate() {
        if let Some(v) = v {
            if !(v.is_finite() && *v >= 0.0) {
                return Err(Error::Invalid(format!("temperature {v} K of surface {} must be finite and ≥ 0", k + 1)));
            }
            temperature[surfaces[k] as usize] = Some(*v);
        }
    }
    let mut copies: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for p in 0..desc.polygons.len() {
        let (m, o) = (desc.polygons[p].material, desc.polygons[p].object);
        let Some(v) = temperature[o as usize] else { continue };
        let next = desc.materials.len() as u32;
        let index = *copies.entry((m, o)).or_insert(next);
        if index == next {
            let mut copy = desc.materials[m as usize].clone();
            let (emissivity, band_emissivity) =
                copy.thermal.take().map(|t| (t.emissivity, t.band_emissivity)).unwrap_or_default();
            copy.thermal = Some(ThermalDesc { emissivity, band_emissivity, boundary: Some(Boundary::Temperature(v)) });
            copy.name = format!("{} ({})", copy.name, desc.objects[o as usize].name);
            desc.materials.push(copy);
        }
        desc.polygons[p].material = index;
    }
    Ok(())
}

/// Gebhart's absorption factors of view factors `f(i, j)` between `n` surfaces of
/// emissivities `eps`: `(I − F diag(1 − ε)) B = F diag(ε)`.
fn gebhart_matrix(n: usize, f: impl Fn(usize, usize) -> f64, eps: &[f64]) -> Mat<f64> {
    let a = Mat::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } - f(i, j) * (1.0 - eps[j]));
    let mut b = Mat::<f64>::from_fn(n, n, |i, j| f(i, j) * eps[j]);
    lu_solve_dense(a, &mut b);
    b
}

/// Hottel's total exchange factors `ℱᵢⱼ = εᵢBᵢⱼ` (script-F; View3D's "emittance-weighted"
/// factors, `emit=1`, which ViewHT reads as `qᵢ = σ Σⱼ ℱᵢⱼ (Tⱼ⁴ − Tᵢ⁴)`) of a row-major
/// `n × n` view-factor matrix `f` and emissivities `eps` in (0, 1]. Rows sum to `εᵢ` in a
/// closed enclosure, less what reaches the environment (an opening, black, absorbs
/// `1 − Σⱼ Fᵢⱼ`); `Aᵢℱᵢⱼ` is symmetric when `AᵢFᵢⱼ` is.
pub fn total_exchange_factors(f: &[f64], eps: &[f64]) -> Result<Vec<f64>> {
    let n = eps.len();
    if f.len() != n * n {
        return Err(Error::Invalid(format!("{} view factors for {n} surfaces (need {})", f.len(), n * n)));
    }
    if let Some((i, e)) = eps.iter().enumerate().find(|(_, e)| !(**e > 0.0 && **e <= 1.0)) {
        return Err(Error::Invalid(format!("emissivity {e} of surface {} is not in (0, 1]", i + 1)));
    }
    if let Some(k) = f.iter().position(|v| !v.is_finite()) {
        return Err(Error::Invalid(format!("view factor [{}][{}] is not a number", k / n + 1, k % n + 1)));
    }
    let b = gebhart_matrix(n, |i, j| f[i * n + j], eps);
    let out: Vec<f64> = (0..n * n).map(|k| eps[k / n] * b[(k / n, k % n)]).collect();
    if out.iter().any(|v| !v.is_finite()) {
        return Err(Error::Invalid("the exchange system is singular".into()));
    }
    Ok(out)
}

/// Largest `|xᵢⱼ − xⱼᵢ| / max(xᵢⱼ, xⱼᵢ)` of an `n × n` matrix of exchange areas
/// (`AᵢFᵢⱼ`, `εᵢAᵢBᵢⱼ` …) over the pairs above 1e-12 of its largest entry.
pub(crate) fn reciprocity_error(n: usize, x: impl Fn(usize, usize) -> f64) -> f64 {
    let big = (0..n * n).map(|k| x(k / n, k % n).abs()).fold(0.0f64, f64::max);
    let mut worst = 0.0f64;
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (x(i, j), x(j, i));
            if a.max(b) > 1e-12 * big {
                worst = worst.max((a - b).abs() / a.max(b));
            }
        }
    }
    worst
}

/// Solves `a x = b` in place of `b` by LU with partial pivoting (faer), consuming `a`.
fn lu_solve_dense(mut a: Mat<f64>, b: &mut Mat<f64>) {
    let (n, k) = (a.nrows(), b.ncols());
    let par = if rayon::current_num_threads() > 1 { Par::rayon(0) } else { Par::Seq };
    let mut perm = vec![0usize; n];
    let mut perm_inv = vec![0usize; n];
    let scratch = factor::lu_in_place_scratch::<usize, f64>(n, n, par, Default::default())
        .or(lu_solve::solve_in_place_scratch::<usize, f64>(n, k, par));
    let mut mem = MemBuffer::new(scratch);
    let (_, pm) =
        factor::lu_in_place(a.as_mut(), &mut perm, &mut perm_inv, par, MemStack::new(&mut mem), Default::default());
    lu_solve::solve_in_place(a.as_ref(), a.as_ref(), pm, b.as_mut(), par, MemStack::new(&mut mem));
}

/// Rows of the front and back element at one place of every two-sided adiabatic material
/// (a radiation shield), matched by object and centroid.
fn shield_pairs(scene: &Scene, mesh: &crate::mesh::Mesh, elements: &[u32]) -> Vec<(usize, usize)> {
    let diag = scene.diagonal().max(f64::MIN_POSITIVE);
    type Sides = (Option<usize>, Option<usize>);
    let mut open: std::collections::HashMap<(u32, [i64; 3]), Sides> = Default::default();
    for (r, &e) in elements.iter().enumerate() {
        let el = &mesh.elements[e as usize];
        let p = &scene.polygons[el.patch as usize];
        let m = &scene.materials[p.material as usize];
        if !(m.two_sided && matches!(m.thermal.as_ref().map(|t| t.boundary), Some(Boundary::Adiabatic))) {
            continue;
        }
        let q = (el.centroid / (1e-7 * diag)).round().to_array().map(|x| x as i64);
        let slot = open.entry((p.object, q)).or_default();
        if p.back_side {
            slot.1 = Some(r);
        } else {
            slot.0 = Some(r);
        }
    }
    let mut pairs: Vec<(usize, usize)> = open.into_values().filter_map(|(f, b)| Some((f?, b?))).collect();
    pairs.sort_unstable();
    pairs
}

/// Exchange factors between surfaces (objects and sides), from the element solution of
/// `Bᵢⱼ = Fᵢⱼ εⱼ + Σₖ Fᵢₖ (1 − εₖ) Bₖⱼ` — Gebhart's absorption factor: the share of the
/// power emitted by `i` that `j` absorbs, directly and after any number of diffuse
/// reflections. Per surface `B_IJ` is the emission-weighted mean over `I`'s elements,
/// `GR_IJ = ε_I A_I B_IJ` the radiative conductance (ESATAN's REF, Thermal Desktop's RADK:
/// `Q_IJ = σ GR_IJ (T_I⁴ − T_J⁴)`), and Hottel's total exchange area `A_I ℱ_IJ = GR_IJ`.
#[derive(Clone, Debug)]
pub struct Exchange {
    /// Surface names (as [`SurfaceResult::name`]).
    pub names: Vec<String>,
    /// Areas.
    pub areas: Vec<f64>,
    /// Emissivities (area means).
    pub emissivity: Vec<f64>,
    /// Gebhart factors `B_IJ`, row-major `n × n`.
    pub gebhart: Vec<f64>,
    /// Share of each surface's emission absorbed by the environment (`1 − Σ_J B_IJ`).
    pub to_environment: Vec<f64>,
    /// Radiative conductances `GR_IJ = ε_I A_I B_IJ`, row-major (scene units²).
    pub conductance: Vec<f64>,
    /// Largest `|GR_IJ − GR_JI| / max(GR_IJ, GR_JI)` over pairs above 1e-12 of the largest.
    pub reciprocity: f64,
    /// Elements of the system.
    pub elements: usize,
}

/// Gebhart factors and radiative conductances of `scene`'s surfaces (emissivity from the
/// materials' thermal data, else `1 − ` mean reflectance; no boundary condition needed).
pub fn exchange_factors(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<Exchange> {
    // Refused before any work.
    if let Some(m) = scene.polygons.iter().map(|p| &scene.materials[p.material as usize]).find(|m| m.thermal.as_ref().is_some_and(|t| !t.band_emissivity.is_empty())) {
        return Err(Error::Invalid(format!(
            "material '{}' has per-band emissivities: Gebhart factors and conductances are grey (give it one emissivity)",
            m.name
        )));
    }
    let vf = VfSettings { per: Per::Element, ..settings.view_factors.clone() };
    let job = Job::new(scene, vf)?;
    let n = job.len();
    if n > MAX_ELEMENTS / 4 {
        return Err(Error::Invalid(format!(
            "{n} elements: Gebhart factors solve an n × n system with n right-hand sides, at most {} elements; \
             raise --mesh-size",
            MAX_ELEMENTS / 4
        )));
    }
    let elements = job.output_elements();
    let vfs = job.compute(None, progress)?;
    let (scene, mesh, f) = (job.scene(), job.mesh(), &vfs.matrix);
    let eps: Vec<f64> = elements
        .iter()
        .map(|&e| {
            let m = &scene.materials[scene.polygons[mesh.elements[e as usize].patch as usize].material as usize];
            m.thermal.as_ref().map_or_else(|| 1.0 - (m.reflectance.x + m.reflectance.y + m.reflectance.z) / 3.0, |t| t.emissivity)
        })
        .collect();
    let b = gebhart_matrix(n, |i, j| f.get(i, j), &eps);
    // Surfaces: (object, side) in order.
    let keys: Vec<(u32, bool)> = elements
        .iter()
        .map(|&e| {
            let p = &scene.polygons[mesh.elements[e as usize].patch as usize];
            (p.object, p.back_side)
        })
        .collect();
    let mut order = keys.clone();
    order.sort();
    order.dedup();
    let of: Vec<usize> = keys.iter().map(|k| order.binary_search(k).unwrap_or(0)).collect();
    let ns = order.len();
    let mut area = vec![0.0; ns];
    let mut ea = vec![0.0; ns];
    let mut gr = vec![0.0; ns * ns];
    for (i, &e) in elements.iter().enumerate() {
        let ai = mesh.elements[e as usize].area;
        area[of[i]] += ai;
        ea[of[i]] += ai * eps[i];
        for j in 0..n {
            gr[of[i] * ns + of[j]] += ai * eps[i] * b[(i, j)];
        }
    }
    if gr.iter().any(|v| !v.is_finite()) {
        return Err(Error::Invalid("the Gebhart system is singular (every surface of emissivity 0?)".into()));
    }
    let gebhart: Vec<f64> = (0..ns * ns).map(|k| if ea[k / ns] > 0.0 { gr[k] / ea[k / ns] } else { 0.0 }).collect();
    let to_environment: Vec<f64> = (0..ns).map(|i| 1.0 - gebhart[i * ns..(i + 1) * ns].iter().sum::<f64>()).collect();
    let reciprocity = reciprocity_error(ns, |i, j| gr[i * ns + j]);
    let two_sided = scene.polygons.iter().any(|p| p.back_side);
    let names = order
        .iter()
        .map(|(o, back)| {
            let name = &scene.objects[*o as usize].name;
            if two_sided && *back {
                format!("{name} (back)")
            } else {
                name.clone()
            }
        })
        .collect();
    let emissivity = (0..ns).map(|i| ea[i] / area[i]).collect();
    Ok(Exchange { names, areas: area, emissivity, gebhart, to_environment, conductance: gr, reciprocity, elements: n })
}
