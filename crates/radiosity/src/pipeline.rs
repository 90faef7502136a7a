//! The pipeline end to end, as the program runs it: scene → mesh → rays → form factors →
//! solve → reconstruct → render. Tests call these functions so that they test what users
//! run.

use std::time::Instant;

use crate::accel::SceneRays;
use crate::form_factor;
use crate::mesh::{self, Mesh, Receivers};
use crate::reconstruct;
use crate::render::gouraud::{self, ElementTracer};
use crate::render::gather;
use crate::render::{Image, PinholeCamera};
use crate::report::{EnergyReport, ObjectReport, Report, Timings};
use crate::scene::{Camera, Scene};
use crate::solve::{self, Solution, Solver, System};
use crate::transport::{SparseRows, Transport};
use crate::{Progress, Result, Rgb};

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
    /// Adaptive refinement of the uniform mesh (None: uniform only); `mesh_size` is then the
    /// size before refinement.
    pub adaptive: Option<mesh::adaptive::Options>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            mesh_size: None,
            form_factors: form_factor::Options::default(),
            solver: Solver::Jacobi,
            solve: solve::Options::default(),
            adaptive: None,
        }
    }
}

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
    /// The form-factor rows.
    pub transport: SparseRows,
    /// Form-factor statistics.
    pub ff_stats: form_factor::Stats,
    /// The solution.
    pub solution: Solution,
    /// Per-vertex radiosity (display values, Gouraud).
    pub vertex_radiosity: Vec<Rgb>,
    /// Stage timings so far.
    pub timings: Timings,
    /// Adaptive refinement, pass by pass (the a priori pass first); empty when uniform.
    pub refinement: Vec<mesh::adaptive::PassStats>,
}

/// Per-element reflectance and emitted exitance.
pub fn element_materials(scene: &Scene, mesh: &Mesh) -> (Vec<Rgb>, Vec<Rgb>) {
    mesh.elements
        .iter()
        .map(|e| {
            let m = &scene.materials[scene.polygons[e.patch as usize].material as usize];
            (m.reflectance, m.exitance())
        })
        .unzip()
}

/// Meshes, builds the BVH, computes form factors and solves. With
/// [`Settings::adaptive`]: uniform mesh → a priori refinement → form factors → solve, then
/// per a posteriori pass: refine on the solution → form factors and coverage of the new
/// mesh, recomputed in full → solve again.
pub fn solve_scene(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<Solved> {
    let mut timings = Timings::default();
    let t = Instant::now();
    let rays = SceneRays::new(&scene.polygons);
    timings.bvh = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let ad = settings.adaptive.as_ref();
    let size = settings.mesh_size.unwrap_or_else(|| mesh::default_size(&scene));
    let mut mesh = mesh::mesh_uniform(&scene, size);
    let mut refinement = Vec::new();
    let mut refiner = None;
    let mut refine_rays = 0;
    if let Some(a) = ad {
        let mut r = mesh::adaptive::Refiner::new(&scene, &mesh);
        let (stats, n) = mesh::adaptive::refine_a_priori(&scene, &rays, &mut r, a);
        refine_rays += n;
        refinement.push(stats);
        mesh = r.mesh().clone();
        refiner = Some(r);
    }
    timings.mesh = t.elapsed().as_secs_f64();

    let mut pass = 0;
    loop {
        let t = Instant::now();
        let receivers = Receivers::compute(&scene, &mesh, &rays);
        let (transport, mut ff_stats) =
            form_factor::compute(&scene, &mesh, &rays, &receivers, &settings.form_factors, progress)?;
        ff_stats.rays += receivers.rays + refine_rays;
        timings.form_factors += t.elapsed().as_secs_f64();

        let t = Instant::now();
        let (rho, emission) = element_materials(&scene, &mesh);
        let area = receivers.open_areas(&mesh);
        let system = System { transport: &transport, reflectance: &rho, emission: &emission, area: &area };
        let solution = solve::solve(settings.solver, &system, &settings.solve, progress)?;
        timings.solve += t.elapsed().as_secs_f64();

        // A posteriori: refine where the indirect light that the final gather interpolates
        // changes fast, then start over on the new mesh.
        if let (Some(a), Some(r)) = (ad, refiner.as_mut()) {
            if pass < a.passes && !progress.should_stop() {
                pass += 1;
                let t = Instant::now();
                let h = indirect_irradiance(&scene, &mesh, &transport, &solution);
                let errors = mesh::adaptive::a_posteriori_errors(&scene, &mesh, &h, &solution.radiosity);
                let stats = r.refine(&errors, a);
                timings.mesh += t.elapsed().as_secs_f64();
                let changed = stats.splits > 0;
                refinement.push(stats);
                if changed {
                    refine_rays = ff_stats.rays; // all rays so far, carried into the next pass
                    mesh = r.mesh().clone();
                    continue;
                }
            }
        }
        let t = Instant::now();
        let vertex_radiosity = reconstruct::vertex_radiosity(&scene, &mesh, &solution.display_radiosity());
        timings.reconstruct = t.elapsed().as_secs_f64();
        return Ok(Solved {
            scene,
            mesh,
            rays,
            receivers,
            transport,
            ff_stats,
            solution,
            vertex_radiosity,
            timings,
            refinement,
        });
    }
}

/// Indirect irradiance per element, `(F·(B − E))_i`: light that has bounced at least once.
pub fn indirect_irradiance(scene: &Scene, mesh: &Mesh, transport: &dyn Transport, solution: &Solution) -> Vec<Rgb> {
    let (_, emission) = element_materials(scene, mesh);
    let b = solution.display_radiosity();
    let reflected: Vec<Rgb> = b.iter().zip(&emission).map(|(b, e)| (*b - *e).max(Rgb::ZERO)).collect();
    let mut h = vec![Rgb::ZERO; b.len()];
    transport.gather(&reflected, &mut h);
    h
}

impl Solved {
    /// Per-object area-averaged radiosity and radiance.
    pub fn objects(&self) -> Vec<ObjectReport> {
        let means = reconstruct::object_means(&self.scene, &self.mesh, &self.solution.radiosity, &self.receivers.open_fraction);
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
            .map(|(k, (o, (area, b)))| ObjectReport {
                name: o.name.clone(),
                area,
                radiosity_rgb: b.to_array(),
                radiance_rgb: (b / std::f64::consts::PI).to_array(),
                elements: counts[k],
                materials: mats[k].clone(),
            })
            .collect()
    }

    /// Energy bookkeeping: emitted = absorbed + escaped + unaccounted.
    pub fn energy(&self) -> EnergyReport {
        let (rho, emission) = element_materials(&self.scene, &self.mesh);
        let b = &self.solution.radiosity;
        let mut fb = vec![Rgb::ZERO; b.len()];
        self.transport.gather(b, &mut fb);
        let mut emitted = Rgb::ZERO;
        let mut absorbed = Rgb::ZERO;
        let mut leaving = Rgb::ZERO;
        let mut arriving = Rgb::ZERO;
        let area = self.receivers.open_areas(&self.mesh);
        for i in 0..self.mesh.len() {
            let a = area[i];
            emitted += emission[i] * a;
            // Irradiance H_i = Σ_j F_ij B_j (gather form); absorbed = A (1−ρ) H.
            absorbed += (Rgb::ONE - rho[i]) * fb[i] * a;
            leaving += b[i] * a;
            arriving += fb[i] * a;
        }
        // Power that leaves surfaces but never arrives anywhere escapes through openings.
        let escaped = leaving - arriving;
        let unaccounted = emitted - absorbed - escaped;
        EnergyReport {
            emitted: emitted.to_array(),
            absorbed: absorbed.to_array(),
            escaped: escaped.to_array(),
            unaccounted: unaccounted.to_array(),
        }
    }

    /// Indirect irradiance per element, `(F·(B − E))_i` — light that has bounced at least
    /// once — and its per-vertex reconstruction (for the final gather).
    pub fn indirect_irradiance(&self) -> (Vec<Rgb>, Vec<Rgb>) {
        let h = indirect_irradiance(&self.scene, &self.mesh, &self.transport, &self.solution);
        let hv = reconstruct::vertex_radiosity(&self.scene, &self.mesh, &h);
        (h, hv)
    }

    /// Renders one view by final gathering (direct light per pixel, indirect from the
    /// solution); `indirect_vertex` comes from [`Solved::indirect_irradiance`]. Returns the
    /// image and the rays cast.
    pub fn render_gather(
        &self,
        camera: &Camera,
        opts: &gather::Options,
        tracer: &ElementTracer,
        indirect_vertex: &[Rgb],
        progress: &dyn Progress,
    ) -> (Image, u64) {
        let cam = PinholeCamera::new(camera, opts.width, opts.height);
        gather::render(&self.scene, &self.mesh, &self.rays, tracer, indirect_vertex, &cam, opts, progress)
    }

    /// Renders one view with Gouraud (or flat) shading.
    pub fn render(&self, camera: &Camera, opts: &gouraud::Options, tracer: &ElementTracer, progress: &dyn Progress) -> Image {
        let cam = PinholeCamera::new(camera, opts.width, opts.height);
        let display = self.solution.display_radiosity();
        gouraud::render(&self.mesh, tracer, &display, &self.vertex_radiosity, &cam, opts, progress)
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
            form_factors: Some(self.ff_stats.clone()),
            solver: Some(s.clone()),
            iterations: s.iterations,
            residual: s.residual,
            rays_cast: self.ff_stats.rays,
            energy: Some(self.energy()),
            timings: self.timings.clone(),
            objects: self.objects(),
            images: Vec::new(),
            views: Vec::new(),
            warnings: self.scene.warnings.iter().map(|w| w.to_string()).collect(),
            refinement: self.refinement.clone(),
        }
    }
}
