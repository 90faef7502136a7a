//! Stage 6: reconstruction — from one radiosity value per element to a smooth function.
//!
//! Per-vertex radiosity is the area-weighted mean of the elements around the vertex
//! (Cohen & Wallace 1993, §9.2), welded across patches that meet at the vertex on the same
//! plane with the same material, and never across creases or material edges, so that
//! Gouraud interpolation hides element boundaries without smearing light round corners.

use std::collections::HashMap;

use glam::DVec3;

use crate::mesh::Mesh;
use crate::scene::Scene;
use crate::Rgb;

/// Radiosity per mesh vertex (index = [`Mesh::positions`] index).
pub fn vertex_radiosity(scene: &Scene, mesh: &Mesh, element_b: &[Rgb]) -> Vec<Rgb> {
    let q = (scene.diagonal() * 1e-7).max(f64::MIN_POSITIVE);
    let mut group_of_vertex = vec![u32::MAX; mesh.positions.len()];
    let mut groups: HashMap<([i64; 3], u32, [i32; 3]), u32> = HashMap::new();
    let mut sums: Vec<(Rgb, f64)> = Vec::new();
    for e in &mesh.elements {
        let poly = &scene.polygons[e.patch as usize];
        let nkey = quantize_normal(poly.normal);
        for k in 0..e.vertex_count() {
            let vi = e.vertices[k] as usize;
            if group_of_vertex[vi] == u32::MAX {
                let p = mesh.positions[vi];
                let key = ([(p.x / q).round() as i64, (p.y / q).round() as i64, (p.z / q).round() as i64], poly.material, nkey);
                let next = sums.len() as u32;
                let g = *groups.entry(key).or_insert(next);
                if g == next {
                    sums.push((Rgb::ZERO, 0.0));
                }
                group_of_vertex[vi] = g;
            }
        }
    }
    for (ei, e) in mesh.elements.iter().enumerate() {
        for k in 0..e.vertex_count() {
            let g = group_of_vertex[e.vertices[k] as usize] as usize;
            sums[g].0 += element_b[ei] * e.area;
            sums[g].1 += e.area;
        }
    }
    group_of_vertex
        .iter()
        .map(|&g| {
            if g == u32::MAX {
                Rgb::ZERO
            } else {
                let (s, w) = sums[g as usize];
                if w > 0.0 {
                    s / w
                } else {
                    Rgb::ZERO
                }
            }
        })
        .collect()
}

fn quantize_normal(n: DVec3) -> [i32; 3] {
    let s = 1e4;
    [(n.x * s).round() as i32, (n.y * s).round() as i32, (n.z * s).round() as i32]
}

/// Area-weighted mean radiosity per object and the object's area. `open_fraction` is the
/// uncovered share of each element: covered area counts as zero radiosity (the convention
/// of the path-traced references), but still counts in the object's area.
pub fn object_means(scene: &Scene, mesh: &Mesh, element_b: &[Rgb], open_fraction: &[f64]) -> Vec<(f64, Rgb)> {
    let mut acc = vec![(0.0, Rgb::ZERO); scene.objects.len()];
    for (ei, e) in mesh.elements.iter().enumerate() {
        let o = scene.polygons[e.patch as usize].object as usize;
        acc[o].0 += e.area;
        acc[o].1 += element_b[ei] * (e.area * open_fraction[ei]);
    }
    acc.into_iter().map(|(a, s)| (a, if a > 0.0 { s / a } else { Rgb::ZERO })).collect()
}
