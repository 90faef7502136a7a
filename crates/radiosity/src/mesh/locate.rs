//! Point location on the mesh: which element of a patch contains a point on that patch.
//! Used wherever a ray hit on a scene polygon must become an element (the stochastic
//! solvers' deposits, the hierarchy's traced rows, the final gather's indirect rays).

use glam::{DVec2, DVec3};

use super::Mesh;
use crate::accel::{Hit, SceneRays};
use crate::sampling::basis;

/// Finds the element of a patch that contains a point on the patch: a uniform grid per
/// patch in the patch's plane, each cell listing the elements whose bounds overlap it, and
/// a point-in-convex-polygon test (the least violated element wins, for points on edges).
pub struct Locator {
    patches: Vec<PatchGrid>,
    /// Per element, its edges in its patch's plane: outward unit normal and offset, so
    /// that `normal·q − offset` is the distance of q outside the edge (unused edges of
    /// triangles repeat the first).
    edges: Vec<[(DVec2, f64); 4]>,
}

struct PatchGrid {
    origin: DVec3,
    axes: (DVec3, DVec3),
    lo: DVec2,
    inv_cell: DVec2,
    nx: usize,
    ny: usize,
    /// Cell c lists `items[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<u32>,
    items: Vec<u32>,
}

impl Locator {
    /// Builds the grids of every patch of `mesh`.
    pub fn new(mesh: &Mesh) -> Self {
        let mut edges = vec![[(DVec2::ZERO, 0.0); 4]; mesh.len()];
        let patches = mesh
            .patches
            .iter()
            .map(|pe| {
                let elems = pe.first..pe.first + pe.count;
                let Some(e0) = mesh.elements.get(pe.first as usize) else {
                    return PatchGrid { origin: DVec3::ZERO, axes: (DVec3::X, DVec3::Y), lo: DVec2::ZERO, inv_cell: DVec2::ONE, nx: 1, ny: 1, cell_start: vec![0, 0], items: Vec::new() };
                };
                let origin = mesh.positions[e0.vertices[0] as usize];
                let axes = basis(e0.normal);
                let to2 = |p: DVec3| DVec2::new((p - origin).dot(axes.0), (p - origin).dot(axes.1));
                let bounds: Vec<(DVec2, DVec2)> = elems
                    .clone()
                    .map(|k| {
                        let (c, n) = mesh.elements[k as usize].corners(&mesh.positions);
                        c[..n].iter().fold((DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)), |(lo, hi), p| {
                            (lo.min(to2(*p)), hi.max(to2(*p)))
                        })
                    })
                    .collect();
                for k in elems.clone() {
                    let (c, n) = mesh.elements[k as usize].corners(&mesh.positions);
                    let v = c.map(to2);
                    // Signed area decides the orientation in this projection.
                    let s = (0..n).map(|i| v[i].perp_dot(v[(i + 1) % n])).sum::<f64>().signum();
                    let mut out = [(DVec2::ZERO, 0.0); 4];
                    for i in 0..4 {
                        let (a, b) = (v[i % n], v[(i + 1) % n]);
                        let e = b - a;
                        let normal = DVec2::new(e.y, -e.x) * s / e.length().max(1e-300);
                        out[i] = (normal, normal.dot(a));
                    }
                    if n == 3 {
                        out[3] = out[0];
                    }
                    edges[k as usize] = out;
                }
                let lo = bounds.iter().fold(DVec2::splat(f64::INFINITY), |m, b| m.min(b.0));
                let hi = bounds.iter().fold(DVec2::splat(f64::NEG_INFINITY), |m, b| m.max(b.1));
                let size = (hi - lo).max(DVec2::splat(1e-300));
                let count = pe.count.max(1) as f64;
                let nx = ((count * size.x / size.y).sqrt().ceil() as usize).clamp(1, 1024);
                let ny = ((count / nx as f64).ceil() as usize).clamp(1, 1024);
                let inv_cell = DVec2::new(nx as f64 / size.x, ny as f64 / size.y);
                let cell_of = |p: DVec2| {
                    let c = (p - lo) * inv_cell;
                    ((c.x.max(0.0) as usize).min(nx - 1), (c.y.max(0.0) as usize).min(ny - 1))
                };
                let mut lists: Vec<Vec<u32>> = vec![Vec::new(); nx * ny];
                for (k, b) in elems.zip(&bounds) {
                    let (x0, y0) = cell_of(b.0);
                    let (x1, y1) = cell_of(b.1);
                    for y in y0..=y1 {
                        for x in x0..=x1 {
                            lists[y * nx + x].push(k);
                        }
                    }
                }
                let mut cell_start = Vec::with_capacity(nx * ny + 1);
                let mut items = Vec::new();
                cell_start.push(0);
                for l in lists {
                    items.extend(l);
                    cell_start.push(items.len() as u32);
                }
                PatchGrid { origin, axes, lo, inv_cell, nx, ny, cell_start, items }
            })
            .collect();
        Locator { patches, edges }
    }

    /// The element whose front a ray from `origin` along `dir` meets, given the ray's first
    /// hit (as [`SceneRays::closest_facing`] returns it); None when the ray leaves the scene
    /// or meets the back of a one-sided face.
    #[inline]
    pub fn front_hit(
        &self,
        mesh: &Mesh,
        rays: &SceneRays,
        origin: DVec3,
        dir: DVec3,
        hit: Option<(Hit, u32)>,
    ) -> Option<u32> {
        let (h, q) = hit?;
        (rays.normal_of(q).dot(dir.as_vec3()) < 0.0).then(|| self.locate(mesh, q, origin + dir * h.t as f64))
    }

    /// The element of `patch` containing `p` (or the nearest, for points a rounding error
    /// outside every element).
    pub fn locate(&self, mesh: &Mesh, patch: u32, p: DVec3) -> u32 {
        let pe = mesh.patches[patch as usize];
        if pe.count == 1 {
            // The only candidate (the test below would return it too): most polygons of a
            // detailed model are one element, and this skips the grid's cache misses.
            return pe.first;
        }
        let g = &self.patches[patch as usize];
        let to2 = |q: DVec3| DVec2::new((q - g.origin).dot(g.axes.0), (q - g.origin).dot(g.axes.1));
        let q = to2(p);
        let c = (q - g.lo) * g.inv_cell;
        let (x, y) = ((c.x.max(0.0) as usize).min(g.nx - 1), (c.y.max(0.0) as usize).min(g.ny - 1));
        let cell = y * g.nx + x;
        let candidates = &g.items[g.cell_start[cell] as usize..g.cell_start[cell + 1] as usize];
        let all: Vec<u32>;
        let candidates = if candidates.is_empty() {
            all = (pe.first..pe.first + pe.count).collect();
            &all[..]
        } else {
            candidates
        };
        let mut best = (f64::INFINITY, candidates[0]);
        for &k in candidates {
            let worst = self.edges[k as usize].iter().map(|(n, c)| n.dot(q) - c).fold(f64::NEG_INFINITY, f64::max);
            if worst <= 0.0 {
                return k;
            }
            if worst < best.0 {
                best = (worst, k);
            }
        }
        best.1
    }
}
