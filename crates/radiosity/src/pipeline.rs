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
    /// Refuse meshes with more elements than this (form factors cost grows as n²).
    pub max_elements: u64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            mesh_size: None,
            form_factors: form_factor::Options::default(),
            solver: Solver::Jacobi,
            solve: solve::Options::default(),
            max_elements: DEFAULT_MAX_ELEMENTS,
        }
    }
}

/// Default cap on the element count.
pub const DEFAULT_MAX_ELEMENTS: u64 = 200_000;

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

/// Meshes, builds the BVH, computes form factors and solves.
pub fn solve_scene(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<Solved> {
    let mut timings = Timings::default();
    let t = Instant::now();
    let size = settings.mesh_size.unwrap_or_else(|| mesh::default_size(&scene));
    let count = mesh::count_uniform(&scene, size);
    if count > settings.max_elements {
        // The smallest size that meets the cap, by bisection on the count.
        let (mut lo, mut hi) = (size, scene.diagonal().max(size));
        for _ in 0..60 {
            let mid = (lo * hi).sqrt();
            if mesh::count_uniform(&scene, mid) > settings.max_elements {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let many = if count == u64::MAX { "more than 10^19".to_string() } else { count.to_string() };
        return Err(crate::Error::Invalid(format!(
            "mesh size {size:.4e} would create {many} elements (limit {}); use --mesh-size {hi:.4e} or larger, or raise --max-elements",
            settings.max_elements
        )));
    }
    let mesh = mesh::mesh_uniform(&scene, size);
    timings.mesh = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let rays = SceneRays::new(&scene.polygons);
    timings.bvh = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let receivers = Receivers::compute(&scene, &mesh, &rays);
    let (transport, mut ff_stats) =
        form_factor::compute(&scene, &mesh, &rays, &receivers, &settings.form_factors, progress)?;
    ff_stats.rays += receivers.rays;
    timings.form_factors = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let (rho, emission) = element_materials(&scene, &mesh);
    let area = receivers.open_areas(&mesh);
    let system = System { transport: &transport, reflectance: &rho, emission: &emission, area: &area };
    let solution = solve::solve(settings.solver, &system, &settings.solve, progress)?;
    timings.solve = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let vertex_radiosity = reconstruct::vertex_radiosity(&scene, &mesh, &solution.display_radiosity());
    timings.reconstruct = t.elapsed().as_secs_f64();
    Ok(Solved { scene, mesh, rays, receivers, transport, ff_stats, solution, vertex_radiosity, timings })
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
        let (_, emission) = element_materials(&self.scene, &self.mesh);
        let b = self.solution.display_radiosity();
        let reflected: Vec<Rgb> = b.iter().zip(&emission).map(|(b, e)| (*b - *e).max(Rgb::ZERO)).collect();
        let mut h = vec![Rgb::ZERO; b.len()];
        self.transport.gather(&reflected, &mut h);
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
        }
    }
}
