//! Validation: [`SceneDesc`] → [`Scene`]. See the rules in the parent module's docs.

use std::collections::HashMap;

use glam::{DVec2, DVec3};

use super::{Material, Object, Polygon, Scene, SceneDesc};
use crate::{Error, Location, Result, Warning};

/// Relative out-of-plane distance (to the polygon's diameter) above which a polygon is
/// treated as non-planar and split into triangles.
const PLANARITY_TOL: f64 = 1e-6;

pub(super) fn validate(desc: SceneDesc) -> Result<Scene> {
    let SceneDesc { name, materials, objects, polygons, camera, two_sided, obstructions, mut warnings } = desc;
    let here = |loc: &Option<Location>| loc.clone().unwrap_or_else(|| Location::file(&name));

    // Materials: physical values only.
    let mut mats = Vec::with_capacity(materials.len());
    for m in &materials {
        let r = m.reflectance.to_array();
        if r.iter().any(|c| !c.is_finite() || *c < 0.0 || *c >= 1.0) {
            return Err(Error::input(
                here(&m.loc),
                format!(
                    "material '{}': reflectance {:?} is outside [0, 1) (a surface cannot reflect more than it receives)",
                    m.name, r
                ),
            ));
        }
        let e = m.emission.to_array();
        if e.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(Error::input(
                here(&m.loc),
                format!("material '{}': emitted radiance {:?} must be finite and non-negative", m.name, e),
            ));
        }
        mats.push(Material {
            name: m.name.clone(),
            reflectance: m.reflectance,
            emission: m.emission,
            two_sided: m.two_sided || two_sided,
        });
    }
    if let Some(cam) = &camera {
        cam.validate().map_err(|msg| Error::input(Location::file(&name), msg))?;
    }

    // Scene scale, for tolerances.
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for p in &polygons {
        for v in &p.vertices {
            if !v.is_finite() {
                return Err(Error::input(
                    here(&p.loc),
                    format!("polygon has a non-finite vertex coordinate {:?}", v.to_array()),
                ));
            }
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    let diag = if lo.x <= hi.x { (hi - lo).length() } else { 0.0 };

    let mut out = Vec::with_capacity(polygons.len());
    let mut skipped = 0usize;
    let mut first_skips: Vec<Warning> = Vec::new();
    let mut split_nonplanar = 0usize;
    let mut first_split: Option<Location> = None;
    for p in &polygons {
        if p.material as usize >= mats.len() || p.object as usize >= objects.len() {
            return Err(Error::input(here(&p.loc), "polygon refers to a material or object that does not exist"));
        }
        let mut pieces: Vec<Vec<DVec3>> = Vec::new();
        match clean_polygon(&p.vertices, diag) {
            Err(why) => {
                skipped += 1;
                if first_skips.len() < 5 {
                    first_skips.push(Warning { loc: p.loc.clone(), msg: format!("skipped degenerate polygon: {why}") });
                }
                continue;
            }
            Ok(Cleaned::Convex(v)) => pieces.push(v),
            Ok(Cleaned::NonPlanar(v)) => {
                split_nonplanar += 1;
                if first_split.is_none() {
                    first_split = p.loc.clone();
                }
                for i in 1..v.len() - 1 {
                    pieces.push(vec![v[0], v[i], v[i + 1]]);
                }
            }
            Ok(Cleaned::Concave(v, n)) => match ear_clip(&v, n) {
                Some(tris) => pieces.extend(tris),
                None => {
                    skipped += 1;
                    if first_skips.len() < 5 {
                        first_skips.push(Warning {
                            loc: p.loc.clone(),
                            msg: "skipped self-intersecting polygon".into(),
                        });
                    }
                    continue;
                }
            },
        }
        let two = mats[p.material as usize].two_sided;
        for v in pieces {
            let nn = super::newell_normal(&v);
            let area = 0.5 * nn.length();
            if !(area > 0.0) || area <= 1e-14 * diag * diag {
                continue;
            }
            let normal = nn / nn.length();
            if two {
                let mut rv = v.clone();
                rv.reverse();
                out.push(Polygon {
                    vertices: rv,
                    normal: -normal,
                    area,
                    material: p.material,
                    object: p.object,
                    back_side: true,
                    two_sided: true,
                    loc: p.loc.clone(),
                });
            }
            out.push(Polygon { vertices: v, normal, area, material: p.material, object: p.object, back_side: false, two_sided: two, loc: p.loc.clone() });
        }
    }
    // Keep front sides before back sides of the same input polygon? Order does not matter
    // for the physics; sort is stable so report order follows input.
    if skipped > 0 {
        warnings.extend(first_skips);
        if skipped > 5 {
            warnings.push(Warning { loc: Some(Location::file(&name)), msg: format!("{skipped} degenerate polygons skipped in all") });
        }
    }
    if split_nonplanar > 0 {
        warnings.push(Warning {
            loc: first_split,
            msg: format!("{split_nonplanar} non-planar polygon(s) split into triangles (v0, vi, vi+1)"),
        });
    }
    drop_duplicates(&mut out, diag, &mut warnings);
    if out.is_empty() {
        return Err(Error::Invalid(format!("{name}: the scene has no usable polygons")));
    }

    // Unique object names: a name used by several objects gets '#k' (k-th, 1-based).
    let mut count: HashMap<&str, usize> = HashMap::new();
    for o in &objects {
        *count.entry(o.name.as_str()).or_default() += 1;
    }
    let mut seen: HashMap<&str, usize> = HashMap::new();
    let objs = objects
        .iter()
        .map(|o| {
            let k = seen.entry(o.name.as_str()).or_default();
            *k += 1;
            if count[o.name.as_str()] > 1 {
                Object { name: format!("{}#{}", o.name, k) }
            } else {
                Object { name: o.name.clone() }
            }
        })
        .collect();

    let mut obstructions = obstructions;
    if let Some(&o) = obstructions.iter().find(|&&o| o as usize >= objects.len()) {
        return Err(Error::Invalid(format!("{name}: obstruction object {o} does not exist")));
    }
    obstructions.sort_unstable();
    obstructions.dedup();
    Ok(Scene { name, materials: mats, objects: objs, polygons: out, camera, warnings, obstructions })
}

/// Removes polygons that repeat an earlier one exactly (the same vertices in the same
/// cyclic order, so the same side faces the same way), with one warning naming the first
/// few. Two coincident copies facing the same way are one surface written twice (an
/// exporter's duplicate, a box pasted onto itself): each would see the full scene, so the
/// receiver's row would count the same surface twice and sum above 1 (issue 9: "absorbed
/// 106 %"). A copy facing the other way is kept: that is how files write two-sided walls.
fn drop_duplicates(polys: &mut Vec<Polygon>, diag: f64, warnings: &mut Vec<Warning>) {
    // Vertices quantised to 1e-9 of the scene size, rotated to start at the smallest.
    let q = 1e-9 * diag.max(f64::MIN_POSITIVE);
    let key = |p: &Polygon| -> Vec<[i64; 3]> {
        let v: Vec<[i64; 3]> =
            p.vertices.iter().map(|x| [(x.x / q).round() as i64, (x.y / q).round() as i64, (x.z / q).round() as i64]).collect();
        let start = (0..v.len()).min_by_key(|&k| v[k]).unwrap_or(0);
        let mut r = v[start..].to_vec();
        r.extend_from_slice(&v[..start]);
        r
    };
    let mut seen: HashMap<Vec<[i64; 3]>, usize> = HashMap::with_capacity(polys.len());
    let mut keep = vec![true; polys.len()];
    let mut dropped = Vec::new();
    for (k, p) in polys.iter().enumerate() {
        match seen.entry(key(p)) {
            std::collections::hash_map::Entry::Occupied(first) => {
                keep[k] = false;
                if !p.back_side {
                    dropped.push((k, *first.get()));
                }
            }
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(k);
            }
        }
    }
    if dropped.is_empty() {
        return;
    }
    let at = |k: usize| polys[k].loc.as_ref().map_or_else(|| format!("polygon {k}"), |l| l.to_string());
    let examples: Vec<String> = dropped.iter().take(3).map(|&(k, f)| format!("{} repeats {}", at(k), at(f))).collect();
    warnings.push(Warning {
        loc: polys[dropped[0].0].loc.clone(),
        msg: format!(
            "skipped {} polygon(s) that duplicate an earlier one exactly (same vertices, same side): {}",
            dropped.len(),
            examples.join("; ")
        ),
    });
    let mut k = 0;
    polys.retain(|_| {
        k += 1;
        keep[k - 1]
    });
}

enum Cleaned {
    Convex(Vec<DVec3>),
    NonPlanar(Vec<DVec3>),
    Concave(Vec<DVec3>, DVec3),
}

/// Removes repeated and collinear vertices and classifies the polygon.
fn clean_polygon(input: &[DVec3], diag: f64) -> std::result::Result<Cleaned, String> {
    let eps = 1e-12 * diag.max(1e-300);
    let mut v: Vec<DVec3> = Vec::with_capacity(input.len());
    for &p in input {
        if v.last().is_none_or(|q: &DVec3| (p - *q).length() > eps) {
            v.push(p);
        }
    }
    while v.len() > 1 && (v[0] - v[v.len() - 1]).length() <= eps {
        v.pop();
    }
    if v.len() < 3 {
        return Err(format!("{} distinct vertices", v.len()));
    }
    let nn = super::newell_normal(&v);
    let area = 0.5 * nn.length();
    let mut diam: f64 = 0.0;
    for a in &v {
        for b in &v {
            diam = diam.max((*a - *b).length());
        }
    }
    if !(area > 1e-12 * diam * diam) || area <= 1e-14 * diag * diag {
        return Err(format!("zero area ({area:e})"));
    }
    let n = nn / nn.length();
    let c = v.iter().copied().sum::<DVec3>() / v.len() as f64;
    let off = v.iter().map(|p| n.dot(*p - c).abs()).fold(0.0, f64::max);
    if v.len() > 3 && off > PLANARITY_TOL * diam {
        return Ok(Cleaned::NonPlanar(v));
    }
    // Drop collinear vertices (turn of ~0 and continuing forward).
    loop {
        let m = v.len();
        if m <= 3 {
            break;
        }
        let mut removed = false;
        for i in 0..m {
            let a = v[(i + m - 1) % m];
            let b = v[i];
            let d = v[(i + 1) % m];
            let e1 = b - a;
            let e2 = d - b;
            if e1.cross(e2).length() <= 1e-10 * e1.length() * e2.length() && e1.dot(e2) > 0.0 {
                v.remove(i);
                removed = true;
                break;
            }
        }
        if !removed {
            break;
        }
    }
    let m = v.len();
    let convex = (0..m).all(|i| {
        let a = v[(i + m - 1) % m];
        let b = v[i];
        let d = v[(i + 1) % m];
        (b - a).cross(d - b).dot(n) > 0.0
    });
    if convex {
        Ok(Cleaned::Convex(v))
    } else {
        Ok(Cleaned::Concave(v, n))
    }
}

/// Ear clipping in the polygon's dominant projection plane. Returns None when no ear can
/// be found (self-intersecting input).
fn ear_clip(v: &[DVec3], n: DVec3) -> Option<Vec<Vec<DVec3>>> {
    let a = n.abs();
    let (ix, iy) = if a.x >= a.y && a.x >= a.z {
        (1, 2)
    } else if a.y >= a.z {
        (2, 0)
    } else {
        (0, 1)
    };
    let sign = n[3 - ix - iy].signum();
    let p2: Vec<DVec2> = v.iter().map(|p| DVec2::new(p[ix], p[iy]) * DVec2::new(1.0, sign)).collect();
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut idx: Vec<usize> = (0..v.len()).collect();
    let mut tris = Vec::new();
    let mut guard = 0;
    while idx.len() > 3 {
        guard += 1;
        if guard > 10 * v.len() * v.len() {
            return None;
        }
        let m = idx.len();
        let mut found = false;
        for k in 0..m {
            let (i0, i1, i2) = (idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]);
            let (a, b, c) = (p2[i0], p2[i1], p2[i2]);
            if cross(a, b, c) <= 0.0 {
                continue;
            }
            let inside = idx.iter().any(|&j| {
                if j == i0 || j == i1 || j == i2 {
                    return false;
                }
                let p = p2[j];
                cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0
            });
            if inside {
                continue;
            }
            tris.push(vec![v[i0], v[i1], v[i2]]);
            idx.remove(k);
            found = true;
            break;
        }
        if !found {
            return None;
        }
    }
    tris.push(vec![v[idx[0]], v[idx[1]], v[idx[2]]]);
    Some(tris)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{MaterialDesc, ObjectDesc, PolygonDesc};
    use crate::Rgb;

    fn desc(polys: Vec<Vec<DVec3>>) -> SceneDesc {
        SceneDesc {
            name: "t".into(),
            materials: vec![MaterialDesc::diffuse("m", Rgb::splat(0.5))],
            objects: vec![ObjectDesc { name: "o".into(), loc: None }],
            polygons: polys
                .into_iter()
                .enumerate()
                .map(|(i, v)| PolygonDesc { vertices: v, material: 0, object: 0, loc: Some(Location::line("t.obj", i + 1)) })
                .collect(),
            ..Default::default()
        }
    }

    #[test]
    fn concave_l_shape_is_triangulated_with_same_area() {
        let l = vec![
            DVec3::new(0., 0., 0.),
            DVec3::new(2., 0., 0.),
            DVec3::new(2., 1., 0.),
            DVec3::new(1., 1., 0.),
            DVec3::new(1., 2., 0.),
            DVec3::new(0., 2., 0.),
        ];
        let s = Scene::from_desc(desc(vec![l])).unwrap();
        let area: f64 = s.polygons.iter().map(|p| p.area).sum();
        assert!((area - 3.0).abs() < 1e-12, "area {area}");
        assert!(s.polygons.iter().all(|p| p.normal.z > 0.999));
    }

    #[test]
    fn degenerate_polygon_is_skipped_with_warning() {
        let good = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
        let bad = vec![DVec3::ZERO, DVec3::X, DVec3::X * 2.0];
        let s = Scene::from_desc(desc(vec![good, bad])).unwrap();
        assert_eq!(s.polygons.len(), 1);
        assert!(s.warnings[0].to_string().contains("t.obj:2"), "{}", s.warnings[0]);
    }

    #[test]
    fn nan_vertex_is_an_error_naming_the_line() {
        let bad = vec![DVec3::ZERO, DVec3::new(f64::NAN, 0., 0.), DVec3::Y];
        let e = Scene::from_desc(desc(vec![vec![DVec3::ZERO, DVec3::X, DVec3::Y], bad])).unwrap_err();
        assert!(e.to_string().starts_with("t.obj:2"), "{e}");
    }

    #[test]
    fn reflectance_of_one_is_rejected() {
        let mut d = desc(vec![vec![DVec3::ZERO, DVec3::X, DVec3::Y]]);
        d.materials[0].reflectance = Rgb::new(0.5, 1.0, 0.5);
        let e = Scene::from_desc(d).unwrap_err();
        assert!(e.to_string().contains("outside [0, 1)"), "{e}");
    }

    #[test]
    fn nonplanar_quad_is_split_like_a_path_tracer() {
        let q = vec![DVec3::ZERO, DVec3::X, DVec3::new(1., 1., 0.1), DVec3::Y];
        let s = Scene::from_desc(desc(vec![q])).unwrap();
        assert_eq!(s.polygons.len(), 2);
        assert_eq!(s.polygons[0].vertices[0], DVec3::ZERO);
    }

    #[test]
    fn repeated_object_names_get_occurrence_suffix() {
        let mut d = desc(vec![vec![DVec3::ZERO, DVec3::X, DVec3::Y]]);
        d.objects = vec![
            ObjectDesc { name: "a".into(), loc: None },
            ObjectDesc { name: "b".into(), loc: None },
            ObjectDesc { name: "a".into(), loc: None },
        ];
        let s = Scene::from_desc(d).unwrap();
        let names: Vec<_> = s.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["a#1", "b", "a#2"]);
    }
}
