//! The view-factor matrix as the `viewfactors` command computes it, for thermal work:
//! scene → elements → f64 rows from any [`form_factor::Method`] → a matrix between input
//! objects or between elements, with [`Diagnostics`] and, for a closed geometry, the
//! [`enclosure`](crate::form_factor::enclosure) correction.
//!
//! `F[i][j]` is the fraction of the energy leaving surface `i` (diffusely, from its front
//! side) that arrives at surface `j`. Per object it is aggregated exactly from element
//! factors, `F_IJ = Σ_{i∈I} A_i Σ_{j∈J} F_ij / A_I` (objects are OBJ `o`/`g` groups, View3D
//! surfaces, …; with two-sided surfaces each side is its own row, named `name (back)`).
//!
//! Elements: with no mesh size given, per-object matrices from the area-to-area methods
//! (analytic, adaptive) use the input polygons whole — they integrate over them to their
//! own accuracy — and every other case meshes to the render default (scene diagonal / 40);
//! a mesh size of 0 means the input polygons (View3D's facets).
//!
//! Obstruction-only surfaces ([`Scene::obstructions`], View3D `O` lines) block rays but
//! get no row or column. Memory: a per-element matrix is held once, dense, after checking
//! that it fits ([`crate::Error::TooLarge`] names the size); [`Job::stream`] hands rows on
//! as they are computed instead, without holding the matrix.

use std::str::FromStr;

use crate::accel::SceneRays;
use crate::form_factor::diagnostics::{Diagnostics, RowDiagnostics};
use crate::form_factor::enclosure::{self, EnclosureReport};
use crate::form_factor::{self, Stats};
use crate::mesh::{self, Mesh, Receivers};
use crate::scene::Scene;
use crate::transport::DenseMatrix;
use crate::{Error, Progress, Result};

/// The unit of the matrix's rows and columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Per {
    /// Input objects (OBJ groups, View3D surfaces).
    Object,
    /// Mesh elements.
    Element,
}

impl Per {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Per::Object => "object",
            Per::Element => "element",
        }
    }
}

impl FromStr for Per {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "object" => Ok(Per::Object),
            "element" => Ok(Per::Element),
            _ => Err(Error::Invalid(format!("unknown --per value '{s}' (known: object, element)"))),
        }
    }
}

/// Everything that decides a view-factor matrix.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Rows per object or per element.
    pub per: Per,
    /// Element size in scene units; `Some(0.0)`: the input polygons; None: see the module
    /// docs.
    pub mesh_size: Option<f64>,
    /// The method and its options.
    pub form_factors: form_factor::Options,
    /// Enforce reciprocity and closure (closed geometry only).
    pub enclosure: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            per: Per::Object,
            mesh_size: None,
            form_factors: form_factor::Options { method: form_factor::Method::Adaptive, ..Default::default() },
            enclosure: false,
        }
    }
}

/// A scene prepared for view factors: its elements and the rows/columns of the output.
pub struct Job {
    scene: Scene,
    mesh: Mesh,
    rays: SceneRays,
    /// Every receiver point open: a view factor counts the whole element, and parts that
    /// see nothing (covered by a box) count as zero.
    receivers: Receivers,
    settings: Settings,
    /// Every group (object side or element), obstructions included.
    groups: Groups,
    /// The groups that are rows/columns of the output, in order.
    output: Vec<usize>,
    /// Rows are whole polygons (area-to-area methods per object), not elements.
    polygon_rows: bool,
}

struct Groups {
    names: Vec<String>,
    areas: Vec<f64>,
    emissivity: Vec<f64>,
    obstruction: Vec<bool>,
    /// Group of each element.
    of_element: Vec<u32>,
    /// Group of each polygon (per object only).
    of_polygon: Vec<u32>,
}

/// A computed matrix with what is known about it.
#[derive(Debug)]
pub struct ViewFactors {
    /// Row/column names.
    pub names: Vec<String>,
    /// Areas in scene units².
    pub areas: Vec<f64>,
    /// Emissivity of each surface (1 − mean reflectance, the grey-body convention).
    pub emissivity: Vec<f64>,
    /// The matrix (rows and columns as `names`).
    pub matrix: DenseMatrix,
    /// Diagnostics of the final matrix.
    pub diagnostics: Diagnostics,
    /// Diagnostics before the enclosure correction, when it was applied.
    pub before_enclosure: Option<Diagnostics>,
    /// What the enclosure correction did.
    pub enclosure: Option<EnclosureReport>,
    /// The form-factor computation.
    pub stats: Stats,
    /// Elements the scene was meshed into.
    pub elements: usize,
}

impl Job {
    /// Meshes the scene and sets up the output's rows and columns.
    pub fn new(scene: Scene, settings: Settings) -> Result<Job> {
        settings.form_factors.validate()?;
        let method = settings.form_factors.method;
        let size = match settings.mesh_size {
            Some(s) if !(s.is_finite() && s >= 0.0) => {
                return Err(Error::Invalid(format!("mesh size must be a non-negative number, got {s}")))
            }
            Some(s) => s,
            None if settings.per == Per::Object && method.is_area_to_area() => 0.0,
            None => mesh::default_size(&scene),
        };
        let polygon_rows = settings.per == Per::Object && method.is_area_to_area() && size == 0.0;
        let mesh = mesh::mesh_uniform(&scene, size);
        let rays = SceneRays::new(&scene.polygons);
        let receivers = Receivers::all_open(&mesh);
        let groups = Groups::new(&scene, &mesh, settings.per);
        let output: Vec<usize> = (0..groups.names.len()).filter(|&g| !groups.obstruction[g]).collect();
        if output.is_empty() {
            return Err(Error::Invalid("the scene has no surfaces to compute view factors for".into()));
        }
        Ok(Job { scene, mesh, rays, receivers, settings, groups, output, polygon_rows })
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Number of surfaces the form factors are computed between: elements, or the input
    /// polygons for the area-to-area methods per object.
    pub fn elements(&self) -> usize {
        if self.polygon_rows {
            self.scene.polygons.len()
        } else {
            self.mesh.len()
        }
    }

    /// Number of output rows (= columns).
    pub fn len(&self) -> usize {
        self.output.len()
    }

    /// True when there is nothing to output (never, after [`Job::new`]).
    pub fn is_empty(&self) -> bool {
        self.output.is_empty()
    }

    /// The meshed scene.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Per element: the mesh element of each output row (per object: the first element
    /// of each row's group is not meaningful; use with [`Per::Element`]).
    pub fn output_elements(&self) -> Vec<u32> {
        self.output.iter().map(|&g| g as u32).collect()
    }

    /// Output names.
    pub fn names(&self) -> Vec<String> {
        self.output.iter().map(|&g| self.groups.names[g].clone()).collect()
    }

    /// Output areas.
    pub fn areas(&self) -> Vec<f64> {
        self.output.iter().map(|&g| self.groups.areas[g]).collect()
    }

    /// Output emissivities.
    pub fn emissivity(&self) -> Vec<f64> {
        self.output.iter().map(|&g| self.groups.emissivity[g]).collect()
    }

    /// Bytes of the dense matrix [`Job::compute`] holds.
    pub fn dense_bytes(&self) -> u64 {
        DenseMatrix::bytes_for(self.work_size())
    }

    /// Groups in the held matrix: all of them when the enclosure needs the obstructions'
    /// rows, else only the output.
    fn work_size(&self) -> usize {
        if self.settings.enclosure {
            self.groups.names.len()
        } else {
            self.output.len()
        }
    }

    /// Computes the whole matrix, held once in memory (`memory_limit` in bytes, None: what
    /// the system has available), with diagnostics and the enclosure correction if asked.
    pub fn compute(&self, memory_limit: Option<u64>, progress: &dyn Progress) -> Result<ViewFactors> {
        let ng = self.groups.names.len();
        // Work index: group → row of the held matrix.
        let work: Vec<usize> = if self.settings.enclosure { (0..ng).collect() } else { self.output.clone() };
        let mut slot = vec![usize::MAX; ng];
        for (k, &g) in work.iter().enumerate() {
            slot[g] = k;
        }
        let nw = work.len();
        let mut m = DenseMatrix::zeros(nw, memory_limit, "the view-factor matrix")?;
        // Rows are the input polygons (area-to-area methods per object) or the elements;
        // each is added, weighted by its area, into its group's row.
        let (of, areas): (&[u32], Vec<f64>) = if self.polygon_rows {
            (&self.groups.of_polygon, self.scene.polygons.iter().map(|p| p.area).collect())
        } else {
            (&self.groups.of_element, self.mesh.elements.iter().map(|e| e.area).collect())
        };
        let rows: Vec<u32> = (0..of.len() as u32).filter(|&i| slot[of[i as usize] as usize] != usize::MAX).collect();
        let mut sink = |i: usize, row: &[(u32, f64)]| {
            let out = m.row_mut(slot[of[i] as usize]);
            for &(j, f) in row {
                let c = slot[of[j as usize] as usize];
                if c != usize::MAX {
                    out[c] += areas[i] * f;
                }
            }
            Ok(())
        };
        let opts = &self.settings.form_factors;
        let stats = if self.polygon_rows {
            form_factor::for_each_polygon_row(&self.scene, &self.rays, opts, Some(&rows), progress, &mut sink)?
        } else {
            form_factor::for_each_row(
                &self.scene,
                &self.mesh,
                &self.rays,
                &self.receivers,
                opts,
                Some(&rows),
                progress,
                &mut sink,
            )?
        };
        let work_areas: Vec<f64> = work.iter().map(|&g| self.groups.areas[g]).collect();
        for (r, a) in work_areas.iter().enumerate() {
            for v in m.row_mut(r) {
                *v /= a;
            }
        }
        let (before, enc) = if self.settings.enclosure {
            let before = Diagnostics::of_dense(&m, &work_areas, None);
            let rep = enclosure::enforce(&mut m, &work_areas)?;
            (Some(before), Some(rep))
        } else {
            (None, None)
        };
        // The output sub-matrix (a copy only when obstructions were part of the work).
        let m = if nw == self.output.len() {
            m
        } else {
            let k = self.output.len();
            let mut o = DenseMatrix::zeros(k, memory_limit, "the view-factor matrix")?;
            for (a, &ga) in self.output.iter().enumerate() {
                for (b, &gb) in self.output.iter().enumerate() {
                    o.set(a, b, m.get(slot[ga], slot[gb]));
                }
            }
            o
        };
        let areas = self.areas();
        let diagnostics = Diagnostics::of_dense(&m, &areas, None);
        Ok(ViewFactors {
            names: self.names(),
            areas,
            emissivity: self.emissivity(),
            matrix: m,
            diagnostics,
            before_enclosure: before,
            enclosure: enc,
            stats,
            elements: self.elements(),
        })
    }

    /// Computes the rows one by one and hands each (dense, output columns) to `sink` in
    /// order, without holding the matrix: for per-element matrices too large for memory.
    /// Reciprocity cannot be checked this way (the diagnostics leave it out), and the
    /// enclosure correction is refused.
    pub fn stream(&self, progress: &dyn Progress, sink: &mut dyn FnMut(&[f64]) -> Result<()>) -> Result<(Diagnostics, Stats)> {
        if self.settings.enclosure {
            return Err(Error::Invalid("the enclosure correction needs the whole matrix in memory".into()));
        }
        if self.settings.per != Per::Element {
            return Err(Error::Invalid("only per-element matrices are streamed".into()));
        }
        let ng = self.groups.names.len();
        let mut slot = vec![usize::MAX; ng];
        for (k, &g) in self.output.iter().enumerate() {
            slot[g] = k;
        }
        let rows: Vec<u32> = self.output.iter().map(|&g| g as u32).collect(); // per element: group = element
        let mut buf = vec![0.0f64; self.output.len()];
        let mut diag = RowDiagnostics::default();
        let mut r = 0usize;
        let stats = form_factor::for_each_row(
            &self.scene,
            &self.mesh,
            &self.rays,
            &self.receivers,
            &self.settings.form_factors,
            Some(&rows),
            progress,
            &mut |_, row| {
                buf.fill(0.0);
                for &(j, f) in row {
                    let c = slot[j as usize];
                    if c != usize::MAX {
                        buf[c] += f;
                    }
                }
                diag.add_row(r, &buf);
                r += 1;
                sink(&buf)
            },
        )?;
        Ok((diag.finish(), stats))
    }
}

impl Groups {
    fn new(scene: &Scene, mesh: &Mesh, per: Per) -> Groups {
        let mut names = Vec::new();
        let mut areas = Vec::new();
        let mut emissivity = Vec::new();
        let mut obstruction = Vec::new();
        let mut of_element = vec![0u32; mesh.len()];
        let mut of_polygon = vec![0u32; scene.polygons.len()];
        let emis = |p: &crate::scene::Polygon| {
            let r = scene.materials[p.material as usize].reflectance;
            1.0 - (r.x + r.y + r.z) / 3.0
        };
        let two_sided = scene.polygons.iter().any(|p| p.back_side);
        match per {
            Per::Object => {
                // Group key: (object, side).
                let mut id = std::collections::HashMap::new();
                for (pi, p) in scene.polygons.iter().enumerate() {
                    let key = (p.object, p.back_side);
                    let g = *id.entry(key).or_insert_with(|| {
                        let o = &scene.objects[p.object as usize];
                        let name = if two_sided && p.back_side { format!("{} (back)", o.name) } else { o.name.clone() };
                        names.push(name);
                        areas.push(0.0);
                        emissivity.push(emis(p));
                        obstruction.push(scene.is_obstruction(p.object));
                        names.len() as u32 - 1
                    });
                    of_polygon[pi] = g;
                    areas[g as usize] += p.area;
                    let pe = mesh.patches[pi];
                    for e in pe.first..pe.first + pe.count {
                        of_element[e as usize] = g;
                    }
                }
                // Report in object order (front before back), not first-polygon order.
                let mut order: Vec<(u32, bool, u32)> =
                    id.iter().map(|(&(o, b), &g)| (o, b, g)).collect();
                order.sort();
                let mut remap = vec![0u32; names.len()];
                let (mut n2, mut a2, mut e2, mut o2) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                for (k, &(_, _, g)) in order.iter().enumerate() {
                    remap[g as usize] = k as u32;
                    n2.push(names[g as usize].clone());
                    a2.push(areas[g as usize]);
                    e2.push(emissivity[g as usize]);
                    o2.push(obstruction[g as usize]);
                }
                for g in of_element.iter_mut().chain(of_polygon.iter_mut()) {
                    *g = remap[*g as usize];
                }
                Groups { names: n2, areas: a2, emissivity: e2, obstruction: o2, of_element, of_polygon }
            }
            Per::Element => {
                let mut count = vec![0usize; scene.objects.len() * 2];
                for (e, el) in mesh.elements.iter().enumerate() {
                    let p = &scene.polygons[el.patch as usize];
                    let k = &mut count[p.object as usize * 2 + p.back_side as usize];
                    let o = &scene.objects[p.object as usize];
                    let side = if two_sided && p.back_side { " (back)" } else { "" };
                    names.push(format!("{}{}:{}", o.name, side, k));
                    *k += 1;
                    areas.push(el.area);
                    emissivity.push(emis(p));
                    obstruction.push(scene.is_obstruction(p.object));
                    of_element[e] = e as u32;
                }
                Groups { names, areas, emissivity, obstruction, of_element, of_polygon }
            }
        }
    }
}

/// Computes a scene's view-factor matrix in one call (see [`Job`]).
pub fn compute(scene: Scene, settings: &Settings, progress: &dyn Progress) -> Result<ViewFactors> {
    Job::new(scene, settings.clone())?.compute(None, progress)
}
