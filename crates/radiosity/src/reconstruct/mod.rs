//! Stage 6: reconstruction — from one radiosity value per element to a smooth function.
//!
//! Interior vertices take the area-weighted average of the elements touching them (Cohen &
//! Wallace 1993, §9.2). At patch boundaries and corners, where those elements all lie on one
//! side, the average would flatten the gradient exactly where a wall meets the ceiling and
//! the light changes fastest; there the value is a local linear least-squares fit of the
//! element values around the vertex (touching elements and their neighbours), evaluated at
//! the vertex — an extrapolation. Vertices are welded across patches that meet on the same
//! plane with the same material, never across creases or material edges, so Gouraud
//! interpolation hides element boundaries without smearing light round corners.

use std::collections::HashMap;

use glam::DVec3;

use crate::mesh::Mesh;
use crate::sampling::basis;
use crate::scene::Scene;
use crate::Rgb;

/// Welded vertex groups: for every mesh vertex its group, and per group the elements
/// that touch it.
pub struct Welding {
    /// Group of each mesh vertex (u32::MAX if unused).
    pub group_of_vertex: Vec<u32>,
    /// Elements touching each group.
    pub elements: Vec<Vec<u32>>,
    /// Position of each group.
    pub position: Vec<DVec3>,
    /// Normal of each group.
    pub normal: Vec<DVec3>,
}

impl Welding {
    /// Welds coincident vertices of coplanar patches with the same material.
    pub fn new(scene: &Scene, mesh: &Mesh) -> Welding {
        let q = (scene.diagonal() * 1e-7).max(f64::MIN_POSITIVE);
        let mut group_of_vertex = vec![u32::MAX; mesh.positions.len()];
        let mut groups: HashMap<([i64; 3], u32, [i32; 3]), u32> = HashMap::new();
        let mut elements: Vec<Vec<u32>> = Vec::new();
        let mut position = Vec::new();
        let mut normal = Vec::new();
        for (ei, e) in mesh.elements.iter().enumerate() {
            let poly = &scene.polygons[e.patch as usize];
            let nkey = quantize_normal(poly.normal);
            for k in 0..e.vertex_count() {
                let vi = e.vertices[k] as usize;
                if group_of_vertex[vi] == u32::MAX {
                    let p = mesh.positions[vi];
                    let key = ([(p.x / q).round() as i64, (p.y / q).round() as i64, (p.z / q).round() as i64], poly.material, nkey);
                    let next = elements.len() as u32;
                    let g = *groups.entry(key).or_insert(next);
                    if g == next {
                        elements.push(Vec::new());
                        position.push(p);
                        normal.push(poly.normal);
                    }
                    group_of_vertex[vi] = g;
                }
                elements[group_of_vertex[vi] as usize].push(ei as u32);
            }
        }
        Welding { group_of_vertex, elements, position, normal }
    }
}

/// Radiosity (or any per-element quantity) per mesh vertex (index = [`Mesh::positions`]).
pub fn vertex_radiosity(scene: &Scene, mesh: &Mesh, element_b: &[Rgb]) -> Vec<Rgb> {
    let w = Welding::new(scene, mesh);
    vertex_values(mesh, &w, element_b)
}

/// Per-vertex values from per-element values with a given welding.
pub fn vertex_values(mesh: &Mesh, w: &Welding, element_b: &[Rgb]) -> Vec<Rgb> {
    let ngroups = w.elements.len();
    let mut group_value = vec![Rgb::ZERO; ngroups];
    let mut ring: Vec<u32> = Vec::new();
    for g in 0..ngroups {
        let ring1 = &w.elements[g];
        // Area-weighted average of the touching elements (the classic rule, and the
        // fallback when a fit is not determined).
        let (mut s, mut a) = (Rgb::ZERO, 0.0);
        for &e in ring1 {
            let el = &mesh.elements[e as usize];
            s += element_b[e as usize] * el.area;
            a += el.area;
        }
        let avg = if a > 0.0 { s / a } else { Rgb::ZERO };
        // Interior vertices (surrounded by their elements) keep the average: a wider fit
        // would blur peaks. Boundary vertices (elements all on one side) extrapolate.
        let (mut c, mut size) = (DVec3::ZERO, 0.0);
        for &e in ring1 {
            let el = &mesh.elements[e as usize];
            c += el.centroid * el.area;
            size += el.area.sqrt() * el.area;
        }
        if a > 0.0 && (c / a - w.position[g]).length() < 0.25 * size / a {
            group_value[g] = avg;
            continue;
        }
        // Second ring: elements sharing a vertex group with the first ring.
        ring.clear();
        for &e in ring1 {
            let el = &mesh.elements[e as usize];
            for k in 0..el.vertex_count() {
                let g2 = w.group_of_vertex[el.vertices[k] as usize];
                for &e2 in &w.elements[g2 as usize] {
                    ring.push(e2);
                }
            }
        }
        ring.sort_unstable();
        ring.dedup();
        group_value[g] = fit_at(mesh, &ring, element_b, w.position[g], w.normal[g]).unwrap_or(avg);
    }
    w.group_of_vertex.iter().map(|&g| if g == u32::MAX { Rgb::ZERO } else { group_value[g as usize] }).collect()
}

/// Weighted linear least squares `v(x) ≈ a + b·u + c·w` over the element centroids (in the
/// plane of `n`), evaluated at `p`; kept near the range of the values used.
fn fit_at(mesh: &Mesh, ring: &[u32], vals: &[Rgb], p: DVec3, n: DVec3) -> Option<Rgb> {
    if ring.len() < 3 {
        return None;
    }
    let (t, b) = basis(n);
    // Normal equations for [1, u, w] with area weights.
    let mut m = [[0.0f64; 3]; 3];
    let mut rhs = [Rgb::ZERO; 3];
    let (mut lo, mut hi) = (Rgb::splat(f64::INFINITY), Rgb::splat(f64::NEG_INFINITY));
    let mut scale: f64 = 0.0;
    for &e in ring {
        let el = &mesh.elements[e as usize];
        let d = el.centroid - p;
        scale = scale.max(d.length());
    }
    if scale <= 0.0 {
        return None;
    }
    for &e in ring {
        let el = &mesh.elements[e as usize];
        let d = (el.centroid - p) / scale;
        let phi = [1.0, d.dot(t), d.dot(b)];
        let wgt = el.area;
        let v = vals[e as usize];
        lo = lo.min(v);
        hi = hi.max(v);
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] += wgt * phi[r] * phi[c];
            }
            rhs[r] += v * (wgt * phi[r]);
        }
    }
    // Solve the 3×3 system by Cramer's rule; we need only the constant term (value at p).
    let det = |a: &[[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d0 = det(&m);
    let norm = m[0][0] * m[1][1] * m[2][2];
    if !(d0.abs() > 1e-9 * norm.abs()) {
        return None;
    }
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mut a = m;
        for r in 0..3 {
            a[r][0] = rhs[r][c];
        }
        *o = det(&a) / d0;
    }
    let v = Rgb::from_array(out);
    if !v.is_finite() {
        return None;
    }
    // Extrapolation beyond the neighbours' range is what boundary vertices need, but keep
    // it within that range again (and non-negative) so noise cannot run away.
    let margin = hi - lo;
    Some(v.clamp((lo - margin).max(Rgb::ZERO), hi + margin))
}

fn quantize_normal(n: DVec3) -> [i32; 3] {
    let s = 1e4;
    [(n.x * s).round() as i32, (n.y * s).round() as i32, (n.z * s).round() as i32]
}

/// Area and area-weighted mean radiosity of one side of an object.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SideMean {
    /// Area (covered parts included).
    pub area: f64,
    /// Mean radiosity (covered parts count as zero).
    pub radiosity: Rgb,
}

/// Per object: its front side (the input winding) and, for two-sided objects, its back
/// side. `open_fraction` is the uncovered share of each element: covered area counts as
/// zero radiosity (the convention of the path-traced references) but still counts in the
/// area.
pub fn object_means(scene: &Scene, mesh: &Mesh, element_b: &[Rgb], open_fraction: &[f64]) -> Vec<(SideMean, SideMean)> {
    let mut acc = vec![(SideMean::default(), SideMean::default()); scene.objects.len()];
    for (ei, e) in mesh.elements.iter().enumerate() {
        let poly = &scene.polygons[e.patch as usize];
        let o = &mut acc[poly.object as usize];
        let side = if poly.back_side { &mut o.1 } else { &mut o.0 };
        side.area += e.area;
        side.radiosity += element_b[ei] * (e.area * open_fraction[ei]);
    }
    for (f, b) in acc.iter_mut() {
        for s in [f, b] {
            if s.area > 0.0 {
                s.radiosity /= s.area;
            }
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::mesh_uniform;
    use crate::scene::{builtin, Scene};

    #[test]
    fn linear_field_is_reproduced_at_boundary_vertices() {
        // B = a + g·x on the Cornell floor: reproduced at every vertex, including the
        // corners where plain averaging would be off by half an element.
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let mesh = mesh_uniform(&scene, 60.0);
        let f = |p: DVec3| 1.0 + 0.01 * p.x + 0.002 * p.z;
        let vals: Vec<Rgb> = mesh.elements.iter().map(|e| Rgb::splat(f(e.centroid))).collect();
        let vb = vertex_radiosity(&scene, &mesh, &vals);
        let floor = mesh.patches[0];
        for e in &mesh.elements[floor.first as usize..(floor.first + floor.count) as usize] {
            for k in 0..e.vertex_count() {
                let v = e.vertices[k] as usize;
                let want = f(mesh.positions[v]);
                // Boundary vertices are fitted exactly; interior ones average the touching
                // elements, exact up to the slight non-uniformity of this trapezoid's grid.
                let p = mesh.positions[v];
                let boundary = p.x.abs() < 1e-9 || p.z.abs() < 1e-9 || (p.z - 559.2).abs() < 1e-9 || p.x > 549.0;
                let tol = if boundary { 1e-9 } else { 1e-4 };
                let got = vb[v].x;
                assert!((got - want).abs() < tol * want, "vertex {v} at {p}: {got} vs {want}");
            }
        }
    }
}
