//! The pipeline end to end, as the program runs it: scene → mesh → rays → form factors →
//! solve → reconstruct → render. Tests call these functions so that they test what users
//! run. The stochastic solvers skip the form factors (they cast rays against the scene's
//! polygons instead); [`solve_all`] runs every solver on one mesh and one set of form factors.
//! With [`Settings::adaptive`] the uniform mesh is refined a priori before the first solve
//! and, per a posteriori pass, on the solution, with coverage and form factors recomputed.

use std::time::Instant;

use crate::accel::SceneRays;
use crate::form_factor;
use crate::mesh::{self, Mesh, Receivers};
use crate::reconstruct;
use crate::render::gather;
use crate::render::gouraud::{self, ElementTracer};
use crate::render::{Image, PinholeCamera};
use crate::report::{ComparisonRow, EnergyReport, ObjectReport, Report, Timings};
use crate::scene::{Camera, Scene};
use crate::solve::{self, IterationState, RaySystem, Solution, Solver, System};
use crate::transport::{self, Operator, Transport};
use crate::{Error, Progress, Result, Rgb};

/// Everything that decides a solution.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Target element size in scene units (None: [`mesh::default_size`]).
    pub mesh_size: Option<f64>,
    /// Form-factor method and sampling.
    pub form_factors: form_factor::Options,
    /// Solver.
    pub solver: Solver,
    /// Stopping rules.
    pub solve: solve::Options,
    /// Refuse meshes with more elements than this (form factors cost grows as n²).
    pub max_elements: u64,
    /// Adaptive refinement of the uniform mesh (None: uniform only); `mesh_size` is then the
    /// size before refinement.
    pub adaptive: Option<mesh::adaptive::Options>,
    /// How the operator is held: explicit rows, hierarchical links, or auto.
    pub transport: transport::Kind,
    /// Element cap when the operator is hierarchical (`max_elements` is the rows' cap).
    pub max_elements_hierarchical: u64,
    /// Link refinement of the hierarchical operator.
    pub links: form_factor::hierarchical::Options,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            mesh_size: None,
            form_factors: form_factor::Options::default(),
            solver: Solver::Chebyshev,
            solve: solve::Options::default(),
            max_elements: DEFAULT_MAX_ELEMENTS,
            adaptive: None,
            transport: transport::Kind::Rows,
            max_elements_hierarchical: DEFAULT_MAX_ELEMENTS_HIERARCHICAL,
            links: form_factor::hierarchical::Options::default(),
        }
    }
}

/// Default cap on the element count (explicit rows: form factors cost grows as n²).
pub const DEFAULT_MAX_ELEMENTS: u64 = 200_000;

/// Default cap on the element count with the hierarchical operator (cost grows as
/// n log n; memory is about 1 kB per element, see BENCHMARKS.md).
pub const DEFAULT_MAX_ELEMENTS_HIERARCHICAL: u64 = 8_000_000;

/// A solved scene.
pub struct Solved {
    /// The scene.
    pub scene: Scene,
    /// Its elements.
    pub mesh: Mesh,
    /// Ray casting against the scene's polygons.
    pub rays: SceneRays,
    /// Receiver points and open (uncovered) fraction of every element.
    pub receivers: Receivers,
    /// The transport operator: form-factor rows or hierarchical links (None for the
    /// stochastic solvers, which never compute them).
    pub transport: Option<Operator>,
    /// Form-factor statistics (None when none were computed).
    pub ff_stats: Option<form_factor::Stats>,
    /// The solution.
    pub solution: Solution,
    /// Per-vertex radiosity (display values, Gouraud).
    pub vertex_radiosity: Vec<Rgb>,
    /// Stage timings so far.
    pub timings: Timings,
    /// Adaptive refinement, pass by pass (empty for a uniform mesh).
    pub refinement: Vec<mesh::adaptive::PassStats>,
    /// Warnings about the solution (e.g. light lost into back faces).
    pub warnings: Vec<String>,
    /// Direct irradiance per element from light that is not a surface's: the sky, its sun
    /// and the point, spot and directional lights (empty without; see [`crate::lights`]).
    pub external_irradiance: Vec<Rgb>,
}

/// Called after solver iterations with the scene and mesh being solved and the state
/// (see [`solve::solve_observed`]); the program draws the frames of `render --frames`.
pub type FrameObserver<'a> = dyn FnMut(&Scene, &Mesh, &IterationState<'_>) + 'a;

/// Per-element reflectance and emitted exitance: the material's, or with a texture its
/// mean over the element's footprint times the factor ([`Scene::surface_means`]).
pub fn element_materials(scene: &Scene, mesh: &Mesh) -> (Vec<Rgb>, Vec<Rgb>) {
    use rayon::prelude::*;
    mesh.elements
        .par_iter()
        .map(|e| {
            let m = &scene.materials[scene.polygons[e.patch as usize].material as usize];
            if m.is_textured() {
                let (corners, n) = e.corners(&mesh.positions);
                let (rho, le) = scene.surface_means(e.patch as usize, &corners[..n]);
                (rho, le * std::f64::consts::PI)
            } else {
                (m.reflectance, m.exitance())
            }
        })
        .unzip()
}

/// Per-element reflectance and the emitted exitance of the linear system: the surfaces' own
/// (`π·Ke`) plus the first reflection `ρ_i · H_ext,i` of light from outside the surfaces
/// (`external` = the direct irradiance from the sky, its sun and the lights,
/// [`crate::lights::element_irradiance`]; empty without).
pub fn system_materials(scene: &Scene, mesh: &Mesh, external: &[Rgb]) -> (Vec<Rgb>, Vec<Rgb>) {
    let (rho, mut emission) = element_materials(scene, mesh);
    for ((e, r), h) in emission.iter_mut().zip(&rho).zip(external) {
        *e += *r * *h;
    }
    (rho, emission)
}

/// Where element `i` comes from, for messages: `file:line (object 'name')`.
pub fn element_place(scene: &Scene, mesh: &Mesh, i: usize) -> String {
    let Some(e) = mesh.elements.get(i) else {
        return format!("element {i}");
    };
    let p = &scene.polygons[e.patch as usize];
    let obj = scene.objects.get(p.object as usize).map_or("?", |o| o.name.as_str());
    let side = if p.back_side { ", back side" } else { "" };
    match &p.loc {
        Some(l) => format!("{l} (object '{obj}'{side})"),
        None => format!("polygon {} (object '{obj}'{side})", e.patch),
    }
}

/// Everything up to the solver: mesh, rays, and the form factors (deterministic solvers
/// only; the stochastic ones cast rays instead).
struct Prepared {
    scene: Scene,
    mesh: Mesh,
    rays: SceneRays,
    receivers: Receivers,
    transport: Option<Operator>,
    ff_stats: Option<form_factor::Stats>,
    reflectance: Vec<Rgb>,
    emission: Vec<Rgb>,
    area: Vec<f64>,
    /// Direct irradiance from the sky, its sun and the lights per element (empty without).
    external_irradiance: Vec<Rgb>,
    timings: Timings,
    refinement: Vec<mesh::adaptive::PassStats>,
    /// Rays cast by refinement so far (counted into the form-factor statistics).
    refine_rays: u64,
    /// The operator kind in use ([`resolve_transport`]).
    kind: transport::Kind,
}

fn prepare(
    scene: Scene,
    settings: &Settings,
    form_factors: bool,
    direct: bool,
    any_solver: bool,
    progress: &dyn Progress,
) -> Result<(Prepared, Option<mesh::adaptive::Refiner>)> {
    let mut timings = Timings::default();
    let t = Instant::now();
    let size = settings.mesh_size.unwrap_or_else(|| mesh::default_size(&scene));
    let count = mesh::count_uniform(&scene, size);
    let patches = scene.polygons.len() as u64;
    let kind = resolve_transport(settings, count, patches, any_solver);
    if settings.transport == transport::Kind::Auto && kind == transport::Kind::Hierarchical {
        progress.message(&format!(
            "transport: {kind} ({patches} polygons, {count} elements; auto picks hierarchical from {} polygons or above {} elements for jacobi, chebyshev and the stochastic solvers)",
            transport::AUTO_PATCHES,
            transport::AUTO_ELEMENTS
        ));
    }
    // Link settings mean nothing to form-factor rows: refused when rows were asked for,
    // warned about when the automatic choice made them moot.
    let moot = settings.links.changed_flags();
    if kind == transport::Kind::Rows && !moot.is_empty() {
        let what = format!("{} set the hierarchical transport's links", moot.join(", "));
        if settings.transport == transport::Kind::Rows {
            return Err(Error::Invalid(format!("{what}; --transport rows computes form-factor rows (drop them, or use --transport hierarchical)")));
        }
        progress.warning(&format!(
            "{what}, which this run does not use: auto picked form-factor rows ({patches} polygons, {count} elements; hierarchical from {} polygons or above {} elements, for jacobi, chebyshev and the stochastic solvers with point-sampled form factors, without --adaptive); --transport hierarchical uses them",
            transport::AUTO_PATCHES,
            transport::AUTO_ELEMENTS
        ));
    }
    let cap = if kind == transport::Kind::Hierarchical { settings.max_elements_hierarchical } else { settings.max_elements };
    if count > cap {
        return Err(Error::Invalid(element_cap_advice(&scene, size, count, cap)));
    }
    let mut mesh = mesh::mesh_uniform_with(&scene, size, progress)?;
    timings.mesh = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let rays = SceneRays::new(&scene.polygons);
    timings.bvh = t.elapsed().as_secs_f64();

    // A priori refinement (direct-light bends, contact lines) before any solve.
    let t = Instant::now();
    let mut refinement = Vec::new();
    let mut refine_rays = 0;
    let refiner = match &settings.adaptive {
        Some(a) => {
            let mut r = mesh::adaptive::Refiner::new(&scene, &mesh);
            let (stats, n) = mesh::adaptive::refine_a_priori(&scene, &rays, &mut r, a, progress);
            refine_rays += n;
            refinement.push(stats);
            mesh = r.mesh().clone();
            Some(r)
        }
        None => None,
    };
    timings.mesh += t.elapsed().as_secs_f64();
    if progress.should_stop() {
        return Err(Error::Cancelled);
    }
    // The direct solver's dense matrix is refused now, not after the form factors.
    if direct {
        solve::direct_check_memory(mesh.len(), settings.solve.direct_memory_limit)?;
    }
    let prepared = Prepared {
        scene,
        mesh,
        rays,
        receivers: Receivers::default(),
        transport: None,
        ff_stats: None,
        reflectance: Vec::new(),
        emission: Vec::new(),
        area: Vec::new(),
        external_irradiance: Vec::new(),
        timings,
        refinement,
        refine_rays,
        kind,
    };
    Ok((prepared.with_factors(settings, form_factors, progress)?, refiner))
}

/// The minimum node size hierarchical links are refined to: the given one, else
/// [`LINK_MIN_SIZE_PER_MESH_SIZE`] × the mesh size above [`transport::AUTO_ELEMENTS`]
/// elements (where refining every pair down to the elements costs minutes: the conference
/// room's 694 163 elements take 730 s of links at 0, 27 s at the mesh size, for the same
/// image error), else 0 (every pair down to the elements: the classroom's per-object median
/// error is 3.8 % at 0 and 6.8 % at the mesh size, where its furniture exchanges light as
/// whole clusters).
pub fn link_min_size(settings: &Settings, mesh: &Mesh) -> f64 {
    settings.links.min_size.unwrap_or(if mesh.len() as u64 > transport::AUTO_ELEMENTS {
        LINK_MIN_SIZE_PER_MESH_SIZE * mesh.target_size
    } else {
        0.0
    })
}

/// The default minimum link size over the mesh size, for scenes above
/// [`transport::AUTO_ELEMENTS`] elements. At 2 (measured 2026-12-05, BENCHMARKS "Eighth
/// round"): Sponza under the sky renders in 45 s instead of 84 s, the conference room in
/// 37 s instead of 54 s, with the same image errors (courtyard 3.33 % / 3.36 %, gallery
/// 11.42 % / 11.74 %, conference 3.41 % / 3.48 %); at 3 Sponza's per-object median error
/// grows to 4.68 % (4.19 % at 1, 4.33 % at 2).
pub const LINK_MIN_SIZE_PER_MESH_SIZE: f64 = 2.0;

/// The error for a mesh size whose uniform mesh has `count` elements, over `limit`: the
/// smallest size that meets the limit (found by bisection on the count, printed rounded up
/// so that it is larger than `size` and still meets the limit) — or, when even one element
/// per polygon is over the limit, that fact and the --max-elements it needs.
fn element_cap_advice(scene: &Scene, size: f64, count: u64, limit: u64) -> String {
    let many = if count == u64::MAX { "more than 10^19".to_string() } else { count.to_string() };
    let least = mesh::count_uniform(scene, f64::INFINITY);
    if least > limit {
        return format!(
            "the scene's {} polygons make at least {least} elements even unsubdivided (one element per quad or \
             triangle), over the limit of {limit}: no --mesh-size can meet it; raise --max-elements to at least {least}",
            scene.polygons.len()
        );
    }
    let (mut lo, mut hi) = (size, scene.diagonal().max(size));
    while mesh::count_uniform(scene, hi) > limit && hi < f64::MAX / 4.0 {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = (lo * hi).sqrt();
        if mesh::count_uniform(scene, mid) > limit {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // The shortest rounding (nearest, else up) that is larger than `size`, prints
    // differently, and still meets the limit.
    let mut suggested = hi;
    'digits: for digits in 1..=17 {
        let scale = 10f64.powi(digits - 1 - hi.log10().floor() as i32);
        for r in [(hi * scale).round() / scale, (hi * scale).ceil() / scale] {
            if r > size && format!("{r}") != format!("{size}") && mesh::count_uniform(scene, r) <= limit {
                suggested = r;
                break 'digits;
            }
        }
    }
    format!(
        "mesh size {size:.4e} would create {many} elements (limit {limit}); use --mesh-size {suggested} or larger, or raise --max-elements"
    )
}

impl Prepared {
    /// (Re)computes coverage, form factors and the per-element system for the current mesh.
    fn with_factors(mut self, settings: &Settings, form_factors: bool, progress: &dyn Progress) -> Result<Prepared> {
        let (scene, mesh, rays) = (&self.scene, &self.mesh, &self.rays);
        let (receivers, transport, ff_stats) = if form_factors {
            let t = Instant::now();
            // The hierarchy's tree (on the elements' full areas; refitted to the open areas
            // after the coverage test) tells how much the links will need: refused now,
            // before the coverage test and the links.
            let mut tree = None;
            let mut predicted_peak = None;
            if self.kind == transport::Kind::Hierarchical {
                let areas: Vec<f64> = mesh.elements.iter().map(|e| e.area).collect();
                progress.begin("tree", 1);
                let built = transport::hierarchical::Tree::build(mesh, &areas);
                progress.end();
                let min_size = link_min_size(settings, mesh);
                let (_, em) = element_materials(scene, mesh);
                let emitters = em.iter().filter(|e| e.max_element() > 0.0).count() as u64;
                // The limit bounds the whole run's peak: what the process holds already
                // counts against it, and the default is what is free beside that.
                let resident = transport::resident_memory().unwrap_or(0);
                let limit = settings
                    .form_factors
                    .memory_limit
                    .or_else(|| transport::available_memory().map(|a| a.saturating_add(resident)));
                let peak = form_factor::hierarchical::predict_peak(&built, min_size, settings.links.separation, emitters, resident);
                if let Some(limit) = limit.filter(|&l| peak.total() > l) {
                    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
                    return Err(Error::TooLarge {
                        what: format!(
                            "a hierarchical run on {} elements (predicted peak: {:.0} MiB held already, {:.0} MiB of links, {:.0} MiB for the rest of the run)",
                            mesh.len(),
                            mib(peak.resident),
                            mib(peak.links),
                            mib(peak.run)
                        ),
                        needed: peak.total(),
                        limit,
                        hint: "use a larger --mesh-size, --link-min-size or --link-separation, or raise --memory-limit"
                            .into(),
                    });
                }
                predicted_peak = Some(peak);
                tree = Some(built);
            }
            let receivers = Receivers::compute_with(scene, mesh, rays, progress);
            if progress.should_stop() {
                return Err(Error::Cancelled);
            }
            check_emitters_open(scene, mesh, rays, &receivers)?;
            let t_sky = Instant::now();
            self.external_irradiance = external_irradiance(scene, mesh, rays, &receivers, progress)?;
            let sky_seconds = t_sky.elapsed().as_secs_f64();
            self.timings.sky += sky_seconds;
            let (transport, mut ff_stats) = match self.kind {
                transport::Kind::Rows | transport::Kind::Auto => {
                    let (rows, stats) = form_factor::compute(scene, mesh, rays, &receivers, &settings.form_factors, progress)?;
                    (Operator::Rows(rows), stats)
                }
                transport::Kind::Hierarchical => {
                    let (rho, em) = system_materials(scene, mesh, &self.external_irradiance);
                    let mut tree = tree.take().expect("built above");
                    tree.refit(mesh, &receivers.open_areas(mesh));
                    let (mut h, rays_cast) = form_factor::hierarchical::link(
                        mesh,
                        rays,
                        &receivers,
                        tree,
                        &rho,
                        &em,
                        &settings.form_factors,
                        &form_factor::hierarchical::Options {
                            min_size: Some(link_min_size(settings, mesh)),
                            ..settings.links.clone()
                        },
                        progress,
                    )?;
                    if let Some(p) = predicted_peak {
                        h.stats.predicted_peak_bytes = p.total();
                        h.stats.resident_before_bytes = p.resident;
                    }
                    let mut warnings = Vec::new();
                    let mut guard = form_factor::RowGuard {
                        rows_corrected: h.stats.rows_scaled,
                        max_row_sum: h.stats.max_row_sum,
                        worst_row: h.stats.worst_row.map(|i| i as usize),
                        ..Default::default()
                    };
                    guard.locate_element(scene, mesh);
                    if h.stats.rows_scaled > 0 {
                        let lifted = h.stats.rows_lifted;
                        let by_links = h.stats.rows_scaled - lifted;
                        let w = format!(
                            "hierarchical links: {} element(s) whose rows summed above 1 had what their links bring scaled so that the row sums to 1 (largest raw sum {:.4} at element {}): \
                             {by_links} by their links alone, which happens near coincident, touching or interpenetrating surfaces{}",
                            h.stats.rows_scaled,
                            h.stats.max_row_sum,
                            guard.worst_place(),
                            if lifted > 0 {
                                format!(", and {lifted} lifted past 1 by the closure fit (their group's rows raised towards its measured closure)")
                            } else {
                                String::new()
                            }
                        );
                        progress.warning(&w);
                        warnings.push(w);
                    }
                    let stats = form_factor::Stats {
                        method: format!("hierarchical ({} leaves)", settings.form_factors.method.name()),
                        nonzeros: h.stats.links,
                        rays: rays_cast,
                        seconds: t.elapsed().as_secs_f64(),
                        warnings,
                        guard,
                        hierarchy: Some(h.stats.clone()),
                    };
                    (Operator::Hierarchical(h), stats)
                }
            };
            ff_stats.rays += receivers.rays + self.refine_rays;
            self.timings.form_factors += t.elapsed().as_secs_f64() - sky_seconds;
            (receivers, Some(transport), Some(ff_stats))
        } else {
            let receivers = Receivers::all_open(mesh);
            let t_sky = Instant::now();
            self.external_irradiance = external_irradiance(scene, mesh, rays, &receivers, progress)?;
            self.timings.sky += t_sky.elapsed().as_secs_f64();
            (receivers, None, None)
        };
        let (reflectance, emission) = system_materials(scene, mesh, &self.external_irradiance);
        // Covered parts of elements neither emit nor reflect: the power formulation and the
        // residual use the open areas.
        self.area = receivers.open_areas(mesh);
        self.reflectance = reflectance;
        self.emission = emission;
        self.receivers = receivers;
        self.transport = transport;
        self.ff_stats = ff_stats;
        Ok(self)
    }

    fn solve(&self, solver: Solver, opts: &solve::Options, progress: &dyn Progress, observer: Option<&mut FrameObserver<'_>>) -> Result<Solution> {
        let (scene, mesh) = (&self.scene, &self.mesh);
        let mut adapter;
        let observer: Option<&mut solve::Observer<'_>> = match observer {
            Some(obs) => {
                adapter = move |s: &IterationState<'_>| obs(scene, mesh, s);
                Some(&mut adapter)
            }
            None => None,
        };
        let result = if solver.is_stochastic() {
            let area = RaySystem::participating_areas(mesh, &self.receivers);
            let sys = RaySystem { mesh, rays: &self.rays, reflectance: &self.reflectance, emission: &self.emission, receivers: &self.receivers, area: &area };
            solve::stochastic::solve(solver, &sys, opts, progress, observer)
        } else {
            let transport = self.transport.as_ref().ok_or_else(|| Error::Invalid("solve without form factors".into()))?;
            let sys = System { transport, reflectance: &self.reflectance, emission: &self.emission, area: &self.area };
            solve::solve_observed(solver, &sys, opts, progress, observer)
        };
        result.map_err(|e| match e {
            Error::Diverged { why, elements, .. } => {
                let places = elements.iter().map(|&i| element_place(scene, mesh, i)).collect();
                Error::Diverged { why, elements, places }
            }
            e => e,
        })
    }

    fn finish(self, mut solution: Solution, solve_seconds: f64, progress: &dyn Progress) -> Solved {
        let mut timings = self.timings;
        timings.solve = solve_seconds;
        if let Some(t) = &self.transport {
            t.release_buffers(); // no product follows soon: the render gathers by rays
        }
        // Split what escaped into openings and back faces, and warn when back faces take much.
        let loss = crate::back_faces::split_escaped(
            &self.scene,
            &self.mesh,
            &self.rays,
            &self.receivers,
            &solution.radiosity,
            &self.area,
            &mut solution.energy,
        );
        let mut warnings = Vec::new();
        form_factor::push_warning(crate::back_faces::warning(&self.scene, &loss, &solution.energy), progress, &mut warnings);
        let cause = match (&self.transport, &self.ff_stats) {
            (_, Some(st)) if st.method == form_factor::Method::Analytic.name() => {
                "analytic form factors ignore occlusion, so surfaces exchange light through what stands between them: \
                 use point-sampled, monte-carlo, hemicube or adaptive form factors"
            }
            (Some(Operator::Hierarchical(h)), _) if h.stats.min_size > 0.0 => {
                "the hierarchical operator's closure fit scales short rows up as a whole and overshoots at coarse link \
                 sizes (BENCHMARKS.md): a smaller --link-min-size reduces it, --transport rows avoids it"
            }
            // Links already reach the elements: no smaller minimum size to suggest.
            (Some(Operator::Hierarchical(_)), _) => {
                "the hierarchical operator's closure fit scales short rows up as a whole and overshoots where surfaces \
                 nearly touch (a lamp just under a ceiling; BENCHMARKS.md): --transport rows avoids it"
            }
            (_, Some(st)) if st.guard.rows_corrected > 0 => {
                "rows of form factors that summed above 1 were scaled, and their columns still send more than \
                 reciprocity allows (see the form-factor warning): a finer --mesh-size or another --form-factors helps"
            }
            (None, None) => "the stochastic estimate is noisy: more --rays reduce it",
            _ => "the form factors are not reciprocal (A_i F_ij differs from A_j F_ji): a finer --mesh-size or more rays helps",
        };
        form_factor::push_warning(crate::back_faces::created_warning(&solution.energy, cause), progress, &mut warnings);
        form_factor::push_warning(crate::back_faces::two_sided_emitter_warning(&self.scene, &solution.energy), progress, &mut warnings);
        form_factor::push_warning(covered_emitters_warning(&self.scene, &self.mesh, &self.receivers), progress, &mut warnings);
        for l in self.scene.lights.iter().filter(|l| crate::lights::enclosed(&self.scene, &self.rays, l, &self.receivers.sides)) {
            let w = format!(
                "{} is inside closed geometry (every ray from it meets the back of a surface): its light reaches no surface",
                light_place(l)
            );
            form_factor::push_warning(Some(w), progress, &mut warnings);
        }
        let t = Instant::now();
        let vertex_radiosity = reconstruct::vertex_radiosity(&self.scene, &self.mesh, &solution.display_radiosity());
        timings.reconstruct = t.elapsed().as_secs_f64();
        Solved {
            scene: self.scene,
            mesh: self.mesh,
            rays: self.rays,
            receivers: self.receivers,
            transport: self.transport,
            ff_stats: self.ff_stats,
            solution,
            vertex_radiosity,
            timings,
            refinement: self.refinement,
            warnings,
            external_irradiance: self.external_irradiance,
        }
    }
}

/// The direct irradiance from the sky, its sun and the lights of every element when the
/// scene has such light (empty otherwise).
fn external_irradiance(scene: &Scene, mesh: &Mesh, rays: &SceneRays, receivers: &Receivers, progress: &dyn Progress) -> Result<Vec<Rgb>> {
    if !scene.has_external_light() {
        return Ok(Vec::new());
    }
    let (s, _) = crate::lights::element_irradiance(scene, mesh, rays, receivers, progress);
    if progress.should_stop() {
        return Err(Error::Cancelled);
    }
    Ok(s)
}

/// The operator `settings.transport` means for a mesh of `count` elements cut from `patches`
/// input polygons: auto picks hierarchical from [`transport::AUTO_PATCHES`] polygons or
/// above [`transport::AUTO_ELEMENTS`] elements when the solver (not every solver:
/// `any_solver`) and the form-factor method allow it.
pub fn resolve_transport(settings: &Settings, count: u64, patches: u64, any_solver: bool) -> transport::Kind {
    match settings.transport {
        transport::Kind::Auto => {
            let solver_ok = !any_solver && check_transport(settings.solver, transport::Kind::Hierarchical).is_ok();
            let method_ok = settings.form_factors.method == form_factor::Method::PointSampled;
            let large = count > transport::AUTO_ELEMENTS || patches >= transport::AUTO_PATCHES;
            if large && solver_ok && method_ok && settings.adaptive.is_none() {
                transport::Kind::Hierarchical
            } else {
                transport::Kind::Rows
            }
        }
        k => k,
    }
}

/// Refuses, before any work, a deterministic solver that needs explicit rows on the
/// hierarchical operator (only Jacobi and Chebyshev multiply by F alone).
pub fn check_transport(solver: Solver, kind: transport::Kind) -> Result<()> {
    if kind == transport::Kind::Hierarchical && !solver.is_stochastic() && !matches!(solver, Solver::Jacobi | Solver::Chebyshev) {
        return Err(Error::Invalid(format!(
            "the {solver} solver reads rows or columns of F, which the hierarchical operator does not store: \
             use --solver jacobi or chebyshev (or a stochastic solver) with --transport hierarchical, or --transport rows"
        )));
    }
    Ok(())
}

/// Refuses a scene whose only light is emitting polygons that the coverage test found
/// wholly covered (inside closed geometry: every probe from them meets the back of a
/// surface) and point or spot lights inside closed geometry. They light nothing, the solution is black, and the energy line and
/// relative residuals divide by an emitted power of zero: a lamp in a closed room whose
/// walls face outward, one-sided, wrote a black image with "emitted 0" and exit 0, and
/// with `--two-sided` (before light told the sides of two-sided polygons apart,
/// [`crate::mesh::lit_sides`]) every solver "diverged" with a residual of
/// infinity naming the lamp, and `--solver direct` printed "absorbed inf %"; a point
/// light alone in such a room gave "emitted 0", exit 0.
fn check_emitters_open(scene: &Scene, mesh: &Mesh, rays: &SceneRays, receivers: &Receivers) -> Result<()> {
    if scene.lit_sky().is_some() {
        return Ok(());
    }
    let (_, emission) = element_materials(scene, mesh);
    let emitting: Vec<usize> = (0..mesh.len()).filter(|&i| emission[i].max_element() > 0.0).collect();
    if (emitting.is_empty() && scene.lights.is_empty()) || emitting.iter().any(|&i| receivers.open_fraction[i] > 0.0) {
        return Ok(());
    }
    if scene.lights.iter().any(|l| !crate::lights::enclosed(scene, rays, l, &receivers.sides)) {
        return Ok(());
    }
    let mut places: Vec<String> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    // Input sides only: a two-sided lamp's back copy is the same line of the file.
    for &i in emitting.iter().filter(|&&i| !scene.polygons[mesh.elements[i].patch as usize].back_side) {
        if seen.insert(mesh.elements[i].patch) && places.len() < 3 {
            places.push(element_place(scene, mesh, i));
        }
    }
    places.extend(scene.lights.iter().take(3 - places.len()).map(light_place));
    let what = match (emitting.is_empty(), scene.lights.is_empty()) {
        (false, true) => "every emitting polygon lies",
        (true, false) => "every light lies",
        _ => "every emitting polygon and every light lie",
    };
    let more = if seen.len() + scene.lights.len() > 3 { ", …" } else { "" };
    Err(Error::Invalid(format!(
        "{what} inside closed geometry, so no light leaves it ({}{more}): every probe ray from them meets the back of \
         a surface first. Are the surfaces around them wound facing away from them (a room whose walls face \
         outward reads as a solid box)? Reverse their winding so that they face the lights, or make them \
         two-sided (--two-sided): then light tells which side of each surface faces it",
        places.join(", ")
    )))
}

/// A light named with where it was given: `file:line: light 'name'`.
fn light_place(l: &crate::scene::Light) -> String {
    let at = l.loc.as_ref().map_or(String::new(), |loc| format!("{loc}: "));
    format!("{at}light '{}'", l.name)
}

/// A warning naming the emitting polygons (input sides; generated back copies aside) that
/// the coverage test found wholly covered while others emit: inside closed geometry, they
/// light nothing (a lamp inside a closed box whose faces point outward reads as inside a
/// solid). [`check_emitters_open`] refuses the run when none is left.
fn covered_emitters_warning(scene: &Scene, mesh: &Mesh, receivers: &Receivers) -> Option<String> {
    if receivers.open_fraction.is_empty() {
        return None;
    }
    let covered: Vec<usize> = (0..scene.polygons.len())
        .filter(|&q| {
            let p = &scene.polygons[q];
            let pe = &mesh.patches[q];
            !p.back_side
                && pe.count > 0
                && scene.materials[p.material as usize].is_emitter()
                && (pe.first..pe.first + pe.count).all(|i| receivers.open_fraction[i as usize] <= 0.0)
        })
        .collect();
    if covered.is_empty() {
        return None;
    }
    let places: Vec<String> = covered.iter().take(3).map(|&q| element_place(scene, mesh, mesh.patches[q].first as usize)).collect();
    let (what, them, it) = if covered.len() == 1 {
        ("1 emitting polygon lies wholly inside closed geometry and lights nothing".to_string(), "it", "it")
    } else {
        (format!("{} emitting polygons lie wholly inside closed geometry and light nothing", covered.len()), "them", "they")
    };
    Some(format!(
        "{what} ({}{}): every probe ray from {them} meets the back of a surface first; if {it} should light the scene, \
         check the winding of the surfaces around {them}",
        places.join(", "),
        if covered.len() > 3 { ", …" } else { "" }
    ))
}

/// Meshes, builds the BVH, computes form factors (not for the stochastic solvers) and
/// solves.
pub fn solve_scene(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<Solved> {
    solve_scene_observed(scene, settings, progress, None)
}

/// [`solve_scene`], calling `observer` after solver iterations (of every adaptive pass).
pub fn solve_scene_observed(
    scene: Scene,
    settings: &Settings,
    progress: &dyn Progress,
    mut observer: Option<&mut FrameObserver<'_>>,
) -> Result<Solved> {
    let stochastic = settings.solver.is_stochastic();
    check_transport(settings.solver, settings.transport)?;
    let (mut prepared, mut refiner) =
        prepare(scene, settings, !stochastic, settings.solver == Solver::Direct, false, progress)?;
    let mut pass = 0;
    let mut seconds = 0.0;
    loop {
        let t = Instant::now();
        let obs: Option<&mut FrameObserver<'_>> = match observer.as_mut() {
            Some(o) => Some(&mut **o),
            None => None,
        };
        let solution = prepared.solve(settings.solver, &settings.solve, progress, obs)?;
        seconds += t.elapsed().as_secs_f64();
        // A posteriori: refine where the indirect light that the final gather interpolates
        // changes fast, then recompute coverage and form factors for the new mesh.
        if let (Some(a), Some(r), Some(transport)) = (&settings.adaptive, refiner.as_mut(), prepared.transport.as_ref()) {
            if pass < a.passes && !progress.should_stop() {
                pass += 1;
                let t = Instant::now();
                let h = indirect_irradiance(&prepared.scene, &prepared.mesh, transport, &solution);
                let errors = mesh::adaptive::a_posteriori_errors(&prepared.scene, &prepared.mesh, &h, &solution.radiosity);
                let stats = r.refine(&errors, a);
                prepared.timings.mesh += t.elapsed().as_secs_f64();
                let changed = stats.splits > 0;
                prepared.refinement.push(stats);
                if changed {
                    prepared.refine_rays = prepared.ff_stats.as_ref().map_or(0, |f| f.rays);
                    prepared.mesh = r.mesh().clone();
                    prepared = prepared.with_factors(settings, true, progress)?;
                    continue;
                }
            }
        }
        return Ok(prepared.finish(solution, seconds, progress));
    }
}

/// Indirect irradiance per element, `(F·(B − E))_i`: the light that has bounced at least
/// once (what the final gather interpolates, and what a posteriori refinement watches).
pub fn indirect_irradiance(scene: &Scene, mesh: &Mesh, transport: &dyn Transport, solution: &Solution) -> Vec<Rgb> {
    let reflected = reflected_radiosity(scene, mesh, solution);
    let mut h = vec![Rgb::ZERO; reflected.len()];
    transport.gather(&reflected, &mut h);
    transport.release_buffers();
    h
}

/// Reflected radiosity `B − E` per element (display values, never negative): the light
/// that has bounced at least once, as it leaves each element.
pub fn reflected_radiosity(scene: &Scene, mesh: &Mesh, solution: &Solution) -> Vec<Rgb> {
    let (_, emission) = element_materials(scene, mesh);
    let b = solution.display_radiosity();
    b.iter().zip(&emission).map(|(b, e)| (*b - *e).max(Rgb::ZERO)).collect()
}

/// One solver's run in [`solve_all`].
#[derive(Clone, Debug)]
pub struct SolverRun {
    /// The solver.
    pub solver: Solver,
    /// Its solution, or why there is none (refused as too large, skipped after an interrupt).
    pub outcome: std::result::Result<Solution, String>,
}

/// Every solver on one scene: the solved scene (holding the reference solution) and each
/// solver's run.
pub struct Comparison {
    /// The scene with the reference solution: `direct` when it ran, else the deterministic
    /// solution with the smallest residual.
    pub solved: Solved,
    /// The reference solver.
    pub reference: Solver,
    /// Every solver, in [`Solver::ALL`] order.
    pub runs: Vec<SolverRun>,
}

/// Runs every solver on one scene with the same mesh, form factors and stopping rules
/// (`settings.solver` is ignored), for comparison. After an interrupt the solver running
/// keeps what it has and the remaining ones are skipped.
pub fn solve_all(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<Comparison> {
    // `direct` refuses for itself here: the other solvers still run.
    let (prepared, _) = prepare(scene, settings, true, false, true, progress)?;
    let mut runs = Vec::new();
    let mut seconds = 0.0;
    for solver in Solver::ALL {
        if progress.should_stop() {
            runs.push(SolverRun { solver, outcome: Err("skipped: interrupted".into()) });
            continue;
        }
        progress.message(&format!("solver {solver}"));
        let t = Instant::now();
        let outcome = match prepared.solve(solver, &settings.solve, progress, None) {
            Ok(s) => Ok(s),
            Err(e @ (Error::TooLarge { .. } | Error::Invalid(_))) => Err(e.to_string()),
            Err(e) => return Err(e),
        };
        seconds += t.elapsed().as_secs_f64();
        runs.push(SolverRun { solver, outcome });
    }
    let reference = runs
        .iter()
        .filter(|r| !r.solver.is_stochastic())
        .filter_map(|r| r.outcome.as_ref().ok().map(|s| (r.solver, s)))
        .min_by(|a, b| {
            let rank = |(solver, s): &(Solver, &Solution)| (*solver != Solver::Direct, s.stats.residual);
            rank(a).partial_cmp(&rank(b)).unwrap_or(std::cmp::Ordering::Equal)
        })
        .map(|(solver, s)| (solver, s.clone()))
        .ok_or(Error::Cancelled)?;
    let (reference, solution) = reference;
    Ok(Comparison { solved: prepared.finish(solution, seconds, progress), reference, runs })
}

impl Comparison {
    /// The comparison table of the report.
    pub fn rows(&self) -> Vec<ComparisonRow> {
        let area: Vec<f64> = self.solved.mesh.elements.iter().map(|e| e.area).collect();
        let reference = &self.solved.solution.radiosity;
        self.runs
            .iter()
            .map(|r| match &r.outcome {
                Ok(s) => {
                    let reached = s.stats.reached(1e-3);
                    ComparisonRow {
                        solver: r.solver.name().to_string(),
                        error: None,
                        seconds_to_1e3: reached.map(|x| x.0),
                        sweeps_to_1e3: reached.map(|x| x.1),
                        difference_from_reference: Some(solve::relative_difference(&area, &s.radiosity, reference)),
                        energy_imbalance: Some(s.energy.relative_imbalance()),
                        stats: Some(s.stats.clone()),
                    }
                }
                Err(e) => ComparisonRow {
                    solver: r.solver.name().to_string(),
                    error: Some(e.clone()),
                    seconds_to_1e3: None,
                    sweeps_to_1e3: None,
                    difference_from_reference: None,
                    energy_imbalance: None,
                    stats: None,
                },
            })
            .collect()
    }

    /// The report: the reference solution's, with the comparison table.
    pub fn report(&self) -> Report {
        let mut report = self.solved.report();
        report.reference_solver = Some(self.reference.name().to_string());
        report.comparison = self.rows();
        report.rays_cast += self
            .runs
            .iter()
            .filter(|r| r.solver != self.reference)
            .filter_map(|r| r.outcome.as_ref().ok())
            .map(|s| s.stats.rays)
            .sum::<u64>();
        report
    }
}

/// Draws element radiosity `element_b` (display values) from `camera`: per-vertex
/// reconstruction, then Gouraud (or flat) rendering — what [`Solved::render`] does, for
/// any radiosity vector (the frames of `render --frames`).
pub fn render_radiosity(
    scene: &Scene,
    mesh: &Mesh,
    tracer: &ElementTracer,
    element_b: &[Rgb],
    camera: &Camera,
    opts: &gouraud::Options,
    progress: &dyn Progress,
) -> Image {
    let cam = PinholeCamera::new(camera, opts.width, opts.height);
    let vertex_b = reconstruct::vertex_radiosity(scene, mesh, element_b);
    let sky = |dir| scene.lit_sky().map_or(Rgb::ZERO, |s| s.radiance_in(dir, 0.0));
    gouraud::render(mesh, tracer, element_b, &vertex_b, &cam, opts, &sky, progress)
}

impl Solved {
    /// Per-object area-averaged radiosity and radiance (front side; back side too for
    /// two-sided objects). Covered parts of elements count as zero.
    pub fn objects(&self) -> Vec<ObjectReport> {
        let means =
            reconstruct::object_means(&self.scene, &self.mesh, &self.solution.radiosity, &self.receivers.open_fraction);
        let mut counts = vec![0usize; self.scene.objects.len()];
        let mut mats: Vec<Vec<String>> = vec![Vec::new(); self.scene.objects.len()];
        for e in &self.mesh.elements {
            let p = &self.scene.polygons[e.patch as usize];
            counts[p.object as usize] += 1;
            let name = &self.scene.materials[p.material as usize].name;
            let list = &mut mats[p.object as usize];
            if !list.contains(name) {
                list.push(name.clone());
            }
        }
        self.scene
            .objects
            .iter()
            .zip(means)
            .enumerate()
            .filter(|(k, _)| counts[*k] > 0)
            .map(|(k, (o, (front, back)))| {
                let pi = std::f64::consts::PI;
                let has_back = back.area > 0.0;
                let (area, b) = if front.area > 0.0 { (front.area, front.radiosity) } else { (back.area, back.radiosity) };
                ObjectReport {
                    name: o.name.clone(),
                    area,
                    radiosity_rgb: b.to_array(),
                    radiance_rgb: (b / pi).to_array(),
                    back_radiosity_rgb: (has_back && front.area > 0.0).then(|| back.radiosity.to_array()),
                    back_radiance_rgb: (has_back && front.area > 0.0).then(|| (back.radiosity / pi).to_array()),
                    elements: counts[k],
                    materials: mats[k].clone(),
                }
            })
            .collect()
    }

    /// The radiosity that tells lit surfaces from dark ones when a camera is checked: the
    /// solution's, or — when the solver stopped before its first iteration (`B = E`:
    /// `--max-iterations 0`) — one bounce of it, `E + ρ·F·E`, where the operator is at hand:
    /// the final gather shows the emitters' direct light whatever the solution holds.
    pub fn lit_radiosity(&self) -> Vec<Rgb> {
        let b = self.solution.display_radiosity();
        let Some(f) = self.transport.as_ref().filter(|_| self.solution.stats.iterations == 0) else {
            return b;
        };
        let (rho, _) = element_materials(&self.scene, &self.mesh);
        let mut fb = vec![Rgb::ZERO; b.len()];
        f.gather(&b, &mut fb);
        f.release_buffers();
        b.iter().zip(&rho).zip(&fb).map(|((b, r), h)| *b + *r * *h).collect()
    }

    /// Indirect irradiance per element — light that has bounced at least once — and its
    /// per-vertex reconstruction (for the final gather). With form factors it is
    /// `(F·(B − E))_i`; without (stochastic solvers) it is `(B − E)/ρ` minus the direct
    /// irradiance sampled at the element's receiver point and the sky's and sun's.
    pub fn indirect_irradiance(&self) -> (Vec<Rgb>, Vec<Rgb>) {
        let (rho, emission) = system_materials(&self.scene, &self.mesh, &self.external_irradiance);
        let b = self.solution.display_radiosity();
        let h: Vec<Rgb> = match &self.transport {
            Some(f) => indirect_irradiance(&self.scene, &self.mesh, f, &self.solution),
            None => {
                let ems = crate::direct::emitters(&self.scene);
                let mut rng = crate::sampling::rng_for(0x1d1, 0);
                let mut pts = Vec::new();
                (0..b.len())
                    .map(|i| {
                        let e = &self.mesh.elements[i];
                        let Some(&x) = self.receivers.points(i, 1).first() else {
                            return Rgb::ZERO;
                        };
                        let total = ((b[i] - emission[i]) / rho[i].max(Rgb::splat(1e-6))).max(Rgb::ZERO);
                        crate::sampling::stratified(4, &mut rng, &mut pts);
                        let (hd, _) =
                            crate::direct::direct_irradiance(&self.scene, &self.rays, &ems, x, e.normal, e.patch, |_| &pts);
                        (total - hd).max(Rgb::ZERO)
                    })
                    .collect()
            }
        };
        let hv = reconstruct::vertex_radiosity(&self.scene, &self.mesh, &h);
        (h, hv)
    }

    /// What the final gather reads as indirect light: gathered by rays from the reflected
    /// radiosity `B − E` of every element (`gathered`), or the indirect irradiance
    /// interpolated from the vertices ([`Solved::indirect_irradiance`]). See
    /// [`gather::Indirect`].
    pub fn indirect(&self, gathered: bool) -> gather::Indirect {
        if gathered {
            let reflected = reflected_radiosity(&self.scene, &self.mesh, &self.solution);
            gather::Indirect::Gathered { reflected, locator: mesh::Locator::new(&self.mesh) }
        } else {
            gather::Indirect::Interpolated(self.indirect_irradiance().1)
        }
    }

    /// The default of [`gather::Options::gather_axis`] for this solution: 0 (interpolated,
    /// noise-free) on form-factor rows, where `F·(B − E)` per element is as good as the
    /// factors (Cornell box: 1.63 % against a path tracer interpolated, 3.83 % gathered with
    /// 2 × 2 rays per position), and on a hierarchy refined down to the elements (minimum
    /// link size 0: office2 at 256² 4.1 % interpolated, 8.8 % gathered; the classroom 5.5 %
    /// interpolated; BENCHMARKS.md "Tenth round"); 2 (gathered) on a hierarchy with a minimum
    /// size, whose coarse links per element are built for transport, not display (on the
    /// conference room the interpolated first bounce is 5 % dark), and for the stochastic
    /// solvers, whose per-element indirect estimate is noisy (classroom 15.4 % interpolated,
    /// 11.2 % gathered). BENCHMARKS.md "Fifth round".
    /// Under a sky the gathered axis is [`gather::SKY_AXIS`]: the gather rays then also
    /// estimate the sky's direct light, whose noise dominates an open scene; with portals
    /// ([`crate::scene::Portal`]) it is 2 again, the portals' own rays taking that light
    /// (Sponza's courtyard: 3.31 % against the path tracer at 2 × 2 with its portal,
    /// 3.25 % at 4 × 4 without; BENCHMARKS.md "Sky portals").
    pub fn default_gather_axis(&self) -> usize {
        match &self.transport {
            Some(Operator::Rows(_)) => 0,
            Some(Operator::Hierarchical(h)) if h.stats.min_size <= 0.0 => 0,
            // Portals take the sky's direct light: the rays then read only what they meet
            // (and sky outside the portals), as without a sky.
            Some(Operator::Hierarchical(_)) | None if self.scene.lit_sky().is_some_and(|s| s.portals.is_empty()) => gather::SKY_AXIS,
            Some(Operator::Hierarchical(_)) | None => 2,
        }
    }

    /// Renders one view by final gathering (direct light per pixel, indirect from the
    /// solution as [`Solved::indirect`] gives it). Returns the image and what it took
    /// (rays, positions).
    pub fn render_gather(
        &self,
        camera: &Camera,
        opts: &gather::Options,
        tracer: &ElementTracer,
        indirect: &gather::Indirect,
        progress: &dyn Progress,
    ) -> (Image, gather::Sampling) {
        let cam = PinholeCamera::new(camera, opts.width, opts.height);
        gather::render(&self.scene, &self.mesh, &self.rays, tracer, indirect, &cam, opts, progress)
    }

    /// Energy bookkeeping: emitted = absorbed + escaped + unshot (see
    /// [`solve::EnergyBalance`]).
    pub fn energy(&self) -> EnergyReport {
        let mut e = EnergyReport::from(&self.solution.energy);
        if self.scene.has_external_light() {
            let incident: Rgb = self
                .mesh
                .elements
                .iter()
                .zip(&self.receivers.open_fraction)
                .zip(&self.external_irradiance)
                .map(|((el, f), h)| *h * (el.area * f))
                .sum();
            e.external_incident = Some(incident.to_array());
            let powers: Vec<Rgb> = self.scene.lights.iter().filter_map(crate::lights::emitted_power).collect();
            if !powers.is_empty() {
                e.lights_power = Some(powers.into_iter().sum::<Rgb>().to_array());
            }
        }
        e
    }

    /// Renders one view with Gouraud (or flat) shading.
    pub fn render(&self, camera: &Camera, opts: &gouraud::Options, tracer: &ElementTracer, progress: &dyn Progress) -> Image {
        let cam = PinholeCamera::new(camera, opts.width, opts.height);
        let display = self.solution.display_radiosity();
        let sky = |dir| self.scene.lit_sky().map_or(Rgb::ZERO, |s| s.radiance_in(dir, 0.0));
        gouraud::render(&self.mesh, tracer, &display, &self.vertex_radiosity, &cam, opts, &sky, progress)
    }

    /// A report with everything but the images and total time filled in.
    pub fn report(&self) -> Report {
        let s = &self.solution.stats;
        Report {
            version: env!("CARGO_PKG_VERSION").to_string(),
            scene: self.scene.name.clone(),
            patches: self.scene.polygons.len(),
            elements: self.mesh.len(),
            mesh_size: self.mesh.target_size,
            form_factors: self.ff_stats.clone(),
            solver: Some(s.clone()),
            iterations: s.iterations,
            residual: s.residual,
            rays_cast: self.ff_stats.as_ref().map_or(0, |f| f.rays) + s.rays,
            energy: Some(self.energy()),
            timings: self.timings.clone(),
            objects: self.objects(),
            images: Vec::new(),
            warnings: self.scene.warnings.iter().map(|w| w.to_string()).chain(self.warnings.iter().cloned()).collect(),
            refinement: self.refinement.clone(),
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin;
    use crate::NoProgress;
    use std::sync::Mutex;

    /// Records the stages begun; stops once `stop_at` is begun (None: never).
    #[derive(Default)]
    struct Stages {
        begun: Mutex<Vec<String>>,
        stop_at: Option<&'static str>,
    }
    impl Progress for Stages {
        fn begin(&self, stage: &str, _total: u64) {
            self.begun.lock().unwrap().push(stage.to_string());
        }
        fn should_stop(&self) -> bool {
            self.stop_at.is_some_and(|s| self.begun.lock().unwrap().iter().any(|b| b == s))
        }
    }

    fn furnace() -> Scene {
        Scene::from_desc(builtin::furnace(0.5, 1.0)).unwrap()
    }

    #[test]
    fn element_cap_below_the_polygon_count_says_so_and_suggests_max_elements() {
        let settings = Settings { mesh_size: Some(10.0), max_elements: 3, ..Default::default() };
        let err = solve_scene(furnace(), &settings, &NoProgress).err().expect("refused").to_string();
        assert!(err.contains("6 polygons") && err.contains("at least 6"), "{err}");
        assert!(err.contains("raise --max-elements to at least 6"), "{err}");
        assert!(!err.contains("--mesh-size 1") && !err.contains("or larger"), "advises a mesh size: {err}");
    }

    #[test]
    fn element_cap_advice_is_a_larger_size_that_meets_the_limit() {
        let scene = furnace();
        for (size, limit) in [(0.01, 600u64), (0.1, 599), (0.5, 23)] {
            let count = mesh::count_uniform(&scene, size);
            assert!(count > limit);
            let msg = element_cap_advice(&scene, size, count, limit);
            let suggested: f64 = msg.split("--mesh-size ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
            assert!(suggested > size, "{msg}");
            assert!(mesh::count_uniform(&scene, suggested) <= limit, "{msg}");
            assert_ne!(format!("{suggested:.4e}"), format!("{size:.4e}"), "{msg}");
        }
    }

    #[test]
    fn direct_solver_too_large_is_refused_before_form_factors() {
        let mut settings = Settings { mesh_size: Some(0.1), solver: Solver::Direct, ..Default::default() };
        settings.solve.direct_memory_limit = 1 << 20; // 600 elements need 2.9 MB
        let progress = Stages::default();
        let err = solve_scene(furnace(), &settings, &progress).err().expect("refused");
        assert!(matches!(err, Error::TooLarge { .. }), "{err}");
        let msg = err.to_string();
        assert!(msg.contains("direct solve of 600 elements") && msg.contains("--solver gauss-seidel"), "{msg}");
        let begun = progress.begun.lock().unwrap().clone();
        assert_eq!(begun, ["mesh"], "stages begun before the refusal");
        // Within the limit it solves.
        settings.solve.direct_memory_limit = 1 << 30;
        assert!(solve_scene(furnace(), &settings, &NoProgress).is_ok());
    }

    #[test]
    fn interrupt_during_meshing_cancels_before_form_factors() {
        let progress = Stages { stop_at: Some("mesh"), ..Default::default() };
        let settings = Settings { mesh_size: Some(0.1), ..Default::default() };
        let err = solve_scene(furnace(), &settings, &progress).err().expect("cancelled");
        assert!(matches!(err, Error::Cancelled), "{err}");
        assert_eq!(*progress.begun.lock().unwrap(), ["mesh"]);
        let err = solve_all(furnace(), &settings, &Stages { stop_at: Some("mesh"), ..Default::default() }).err().unwrap();
        assert!(matches!(err, Error::Cancelled), "{err}");
    }
}
