//! A scene from vertex and face arrays — the input of the Python package and of programs
//! that hold their geometry in memory (pyviewfactor's, uDALES's, a CAD export).
//!
//! Each face is a planar polygon given by vertex indices (front side by the right-hand
//! rule). Faces are grouped into *surfaces* by an integer label (default: every face its
//! own surface, labelled by its index); a surface is one object with its own material,
//! named by its label, so results per object are results per surface in increasing label
//! order. Obstruction faces block rays but get no row or column.

use glam::DVec3;

use super::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
use crate::{Error, Result, Rgb};

/// Geometry as arrays.
#[derive(Clone, Copy, Debug)]
pub struct Arrays<'a> {
    /// Vertex positions.
    pub vertices: &'a [[f64; 3]],
    /// Faces: vertex indices, three or more each.
    pub faces: &'a [Vec<usize>],
    /// Surface label per face (empty: every face its own surface, labelled by its index).
    pub labels: &'a [i64],
    /// Per face: only blocks (empty: none does).
    pub obstruction: &'a [bool],
}

/// A scene from arrays: the description (object `k` = surface `surfaces[k]`, material
/// `k` its own; obstruction faces follow, one object each) and the surface labels in order.
pub fn scene_from_arrays(a: &Arrays) -> Result<(SceneDesc, Vec<i64>)> {
    let nf = a.faces.len();
    if nf == 0 {
        return Err(Error::Invalid("no faces".into()));
    }
    if !a.labels.is_empty() && a.labels.len() != nf {
        return Err(Error::Invalid(format!("{} surface labels for {nf} faces", a.labels.len())));
    }
    if !a.obstruction.is_empty() && a.obstruction.len() != nf {
        return Err(Error::Invalid(format!("{} obstruction flags for {nf} faces", a.obstruction.len())));
    }
    if let Some(k) = a.vertices.iter().position(|v| !v.iter().all(|x| x.is_finite())) {
        return Err(Error::Invalid(format!("vertex {k} has a coordinate that is not a finite number")));
    }
    let blocks = |f: usize| a.obstruction.get(f).copied().unwrap_or(false);
    let label = |f: usize| a.labels.get(f).copied().unwrap_or(f as i64);
    let mut surfaces: Vec<i64> = (0..nf).filter(|&f| !blocks(f)).map(label).collect();
    surfaces.sort_unstable();
    surfaces.dedup();
    if surfaces.is_empty() {
        return Err(Error::Invalid("every face is an obstruction: no surface to compute for".into()));
    }
    let mut desc = SceneDesc { name: "arrays".into(), ..Default::default() };
    for s in &surfaces {
        desc.objects.push(ObjectDesc { name: s.to_string(), loc: None });
        desc.materials.push(MaterialDesc::diffuse(&format!("surface {s}"), Rgb::ZERO));
    }
    for (f, face) in a.faces.iter().enumerate() {
        if face.len() < 3 {
            return Err(Error::Invalid(format!("face {f} has {} vertices (3 or more needed)", face.len())));
        }
        let mut vertices = Vec::with_capacity(face.len());
        for &v in face {
            let p = a.vertices.get(v).ok_or_else(|| {
                Error::Invalid(format!("face {f}: vertex index {v} out of range ({} vertices)", a.vertices.len()))
            })?;
            vertices.push(DVec3::from_array(*p));
        }
        let object = if blocks(f) {
            let o = desc.objects.len() as u32;
            desc.objects.push(ObjectDesc { name: format!("obstruction {f}"), loc: None });
            desc.materials.push(MaterialDesc::diffuse(&format!("obstruction {f}"), Rgb::ZERO));
            desc.obstructions.push(o);
            o
        } else {
            surfaces.binary_search(&label(f)).unwrap_or(0) as u32
        };
        desc.polygons.push(PolygonDesc { uvs: Vec::new(), vertices, material: object, object, loc: None });
    }
    Ok((desc, surfaces))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn labels_group_faces_and_obstructions_get_no_surface() {
        let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let faces = vec![vec![0, 1, 2], vec![0, 2, 3], vec![0, 1, 3]];
        let (d, s) =
            scene_from_arrays(&Arrays { vertices: &v, faces: &faces, labels: &[7, 7, 3], obstruction: &[] }).unwrap();
        assert_eq!(s, vec![3, 7]);
        assert_eq!(d.polygons.iter().map(|p| p.object).collect::<Vec<_>>(), vec![1, 1, 0]);
        let (d, s) =
            scene_from_arrays(&Arrays { vertices: &v, faces: &faces, labels: &[], obstruction: &[false, true, false] })
                .unwrap();
        assert_eq!(s, vec![0, 2]);
        assert_eq!(d.obstructions, vec![2]);
        assert!(Scene::from_desc(d).is_ok());
        let bad = vec![vec![0, 1, 9]];
        let e = scene_from_arrays(&Arrays { vertices: &v, faces: &bad, labels: &[], obstruction: &[] }).unwrap_err();
        assert!(e.to_string().contains("face 0: vertex index 9 out of range"), "{e}");
    }
}
