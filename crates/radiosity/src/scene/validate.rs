//! Validation: [`SceneDesc`] → [`Scene`]. See the rules in the parent module's docs.

use std::collections::HashMap;

use glam::{DVec2, DVec3};

use super::{Boundary, ThermalDesc, ThermalSpec};
use super::{Material, Object, Polygon, Scene, SceneDesc, MAX_COORDINATE, MAX_EMISSION, MAX_POLYGON_VERTICES, MAX_REFLECTANCE};
use crate::{Error, Location, Result, Warning};

/// Largest angular diameter of a sun, degrees (a disk much wider is a sky, not a sun).
pub const MAX_SUN_DIAMETER_DEG: f64 = 20.0;

/// Relative out-of-plane distance (to the polygon's diameter) above which a polygon is
/// treated as non-planar and split into triangles.
pub const PLANARITY_TOL: f64 = 1e-6;

pub(super) fn validate(desc: SceneDesc) -> Result<Scene> {
    let SceneDesc {
        name,
        materials,
        objects,
        polygons,
        camera,
        two_sided,
        obstructions,
        mut warnings,
        strict,
        ignored_lights,
        sky,
        lights,
        textures,
        band_edges,
        node_tree,
    } = desc;
    // The scene's file: where its polygons came from (built-in scenes: the name).
    let file = polygons.iter().find_map(|p| p.loc.as_ref().map(|l| l.file.clone())).unwrap_or_else(|| name.clone().into());
    let here = |loc: &Option<Location>| loc.clone().unwrap_or_else(|| Location::file(&file));

    // Materials: physical values only.
    let mut mats = Vec::with_capacity(materials.len());
    let mut capped: Vec<String> = Vec::new();
    let mut tex_capped: Vec<String> = Vec::new();
    for m in &materials {
        let r = m.reflectance.to_array();
        if r.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(Error::input(
                here(&m.loc),
                format!("material '{}': reflectance {:?} must be finite and non-negative", m.name, r),
            ));
        }
        let mut reflectance = m.reflectance;
        // With a texture the factor may be 1 (glTF's default): the product is capped per
        // texel read instead ([`super::Scene::reflectance_at`]).
        if m.base_texture.is_none() && r.iter().any(|c| *c >= 1.0) {
            if strict {
                return Err(Error::input(
                    here(&m.loc),
                    format!(
                        "material '{}': reflectance {:?} is outside [0, 1) (a surface cannot reflect more than it \
                         receives; strict mode refuses it instead of lowering it to {MAX_REFLECTANCE})",
                        m.name, r
                    ),
                ));
            }
            reflectance = crate::Rgb::from_array(r.map(|c| c.min(MAX_REFLECTANCE)));
            capped.push(match &m.loc {
                Some(l) => format!("'{}' ({l})", m.name),
                None => format!("'{}'", m.name),
            });
        }
        let e = m.emission.to_array();
        if e.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(Error::input(
                here(&m.loc),
                format!("material '{}': emitted radiance {:?} must be finite and non-negative", m.name, e),
            ));
        }
        if e.iter().any(|c| *c > MAX_EMISSION) {
            return Err(Error::input(
                here(&m.loc),
                format!(
                    "material '{}': emitted radiance {:?} is above {MAX_EMISSION:e}, where emitted power would \
                     overflow; rescale the emission",
                    m.name, e
                ),
            ));
        }
        // Textures multiply the factors; the material's constants become their means.
        let mut texture = |t: &Option<super::TextureRef>, factor: crate::Rgb, what: &str| -> Result<Option<(super::TextureRef, crate::Rgb)>> {
            let Some(t) = t else { return Ok(None) };
            let Some(img) = textures.get(t.texture as usize) else {
                return Err(Error::input(
                    here(&m.loc),
                    format!("material '{}': {what} texture {} does not exist ({} textures)", m.name, t.texture, textures.len()),
                ));
            };
            if (img.max * factor).max_element() >= 1.0 && what == "reflectance" {
                tex_capped.push(format!("'{}' ({})", m.name, img.name));
            }
            Ok(Some((t.clone(), factor)))
        };
        let base_texture = texture(&m.base_texture, reflectance, "reflectance")?;
        let emission_texture = texture(&m.emission_texture, m.emission, "emission")?;
        let mean = |t: &Option<(super::TextureRef, crate::Rgb)>, c: crate::Rgb| match t {
            Some((r, f)) => textures[r.texture as usize].mean * *f,
            None => c,
        };
        let thermal = match &m.thermal {
            Some(ThermalDesc { emissivity, band_emissivity, boundary: Some(boundary) }) => {
                let boundary = *boundary;
                let eps = emissivity.unwrap_or_else(|| 1.0 - (reflectance.x + reflectance.y + reflectance.z) / 3.0);
                let bad = |msg: String| Error::input(here(&m.loc), format!("material '{}': {msg}", m.name));
                if !(0.0..=1.0).contains(&eps) {
                    return Err(bad(format!("emissivity {eps} must be between 0 and 1")));
                }
                if let Some(e) = band_emissivity.iter().find(|e| !(0.0..=1.0).contains(*e)) {
                    return Err(bad(format!("band emissivity {e} must be between 0 and 1")));
                }
                if band_emissivity.len() == 1 {
                    return Err(bad("one band emissivity: give one number for a grey surface, or one per band".into()));
                }
                match boundary {
                    Boundary::Temperature(t) if !(t.is_finite() && t >= 0.0) => {
                        return Err(bad(format!("temperature {t} K must be finite and ≥ 0 (kelvin)")))
                    }
                    Boundary::HeatFlux(q) if !q.is_finite() => return Err(bad(format!("heat flux {q} must be finite"))),
                    Boundary::HeatFlux(q) if q != 0.0 && (band_emissivity.is_empty() && eps <= 0.0 || !band_emissivity.is_empty() && band_emissivity.iter().all(|e| *e <= 0.0)) => {
                        return Err(bad("a surface of emissivity 0 cannot emit or absorb a heat flux".into()))
                    }
                    _ => {}
                }
                Some(ThermalSpec { emissivity: eps, band_emissivity: band_emissivity.clone(), boundary })
            }
            _ => None,
        };
        mats.push(Material {
            thermal,
            name: m.name.clone(),
            reflectance: mean(&base_texture, reflectance).min(crate::Rgb::splat(MAX_REFLECTANCE)),
            emission: mean(&emission_texture, m.emission),
            two_sided: m.two_sided.unwrap_or(two_sided),
            base_texture,
            emission_texture,
        });
    }
    if let Some(sky) = &sky {
        let e = sky.radiance.to_array();
        if e.iter().any(|c| !c.is_finite() || *c < 0.0 || *c > MAX_EMISSION) {
            return Err(Error::input(
                Location::file(&file),
                format!("sky radiance {e:?} must be finite, non-negative and at most {MAX_EMISSION:e}"),
            ));
        }
        if let Some(sun) = &sky.sun {
            let e = sun.irradiance.to_array();
            let d = sun.direction;
            let why = if e.iter().any(|c| !c.is_finite() || *c < 0.0 || *c > MAX_EMISSION) {
                Some(format!("irradiance {e:?} must be finite, non-negative and at most {MAX_EMISSION:e}"))
            } else if !d.is_finite() || d.length() < 1e-12 {
                Some(format!("direction {:?} must be a finite, non-zero vector", d.to_array()))
            } else if !(0.0..=MAX_SUN_DIAMETER_DEG).contains(&sun.angular_diameter_deg) {
                Some(format!("angular diameter {} must be between 0 and {MAX_SUN_DIAMETER_DEG} degrees", sun.angular_diameter_deg))
            } else {
                None
            };
            if let Some(why) = why {
                return Err(Error::input(Location::file(&file), format!("sun: {why}")));
            }
        }
    }
    let lights = validate_lights(lights, &file)?;
    let sky = sky.map(|mut s| {
        if let Some(sun) = &mut s.sun {
            sun.direction = sun.direction.normalize();
        }
        s
    });
    if !capped.is_empty() {
        warnings.push(Warning {
            loc: Some(Location::file(&file)),
            msg: format!(
                "reflectance ≥ 1 lowered to {MAX_REFLECTANCE} (a surface that reflects everything never absorbs) \
                 in {} material(s): {}",
                capped.len(),
                capped.join(", ")
            ),
        });
    }
    if !tex_capped.is_empty() {
        warnings.push(Warning {
            loc: Some(Location::file(&file)),
            msg: format!(
                "texels whose reflectance (texture × factor) reaches 1 are lowered to {MAX_REFLECTANCE} in {} \
                 material(s): {}",
                tex_capped.len(),
                tex_capped.join(", ")
            ),
        });
    }
    if let Some(cam) = &camera {
        cam.validate().map_err(|msg| Error::input(Location::file(&file), msg))?;
    }

    // Scene scale, for tolerances.
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for p in &polygons {
        if p.vertices.len() > MAX_POLYGON_VERTICES {
            return Err(Error::input(
                here(&p.loc),
                format!(
                    "polygon has {} vertices; at most {MAX_POLYGON_VERTICES} are supported (split it into smaller \
                     polygons)",
                    p.vertices.len()
                ),
            ));
        }
        for v in &p.vertices {
            if !v.is_finite() {
                return Err(Error::input(
                    here(&p.loc),
                    format!("polygon has a non-finite vertex coordinate {:?}", v.to_array()),
                ));
            }
            if v.abs().max_element() > MAX_COORDINATE {
                return Err(Error::input(
                    here(&p.loc),
                    format!(
                        "polygon has a vertex coordinate {:?} of magnitude above {MAX_COORDINATE:e}, where areas and \
                         squared distances overflow; rescale the scene",
                        v.to_array()
                    ),
                ));
            }
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    let diag = if lo.x <= hi.x { (hi - lo).length() } else { 0.0 };

    let mut out = Vec::with_capacity(polygons.len());
    let mut degenerate = Skips::default();
    let mut crossing = Skips::default();
    let mut tiny = Skips::default();
    let mut lost_emitters = Skips::default();
    let mut split_nonplanar = 0usize;
    let mut first_split: Option<Location> = None;
    for p in &polygons {
        if p.material as usize >= mats.len() || p.object as usize >= objects.len() {
            return Err(Error::input(here(&p.loc), "polygon refers to a material or object that does not exist"));
        }
        let emits = mats[p.material as usize].is_emitter();
        if let Some(bad) = p.uvs.iter().find(|set| set.len() != p.vertices.len() || set.iter().any(|t| !t.is_finite())) {
            return Err(Error::input(
                here(&p.loc),
                format!(
                    "polygon has {} vertices but {} texture coordinates (or a non-finite one)",
                    p.vertices.len(),
                    bad.len()
                ),
            ));
        }
        let uv: Vec<super::UvMap> = p.uvs.iter().map(|set| super::UvMap::fit(&p.vertices, set)).collect();
        let mut pieces: Vec<Vec<DVec3>> = Vec::new();
        match clean_polygon(&p.vertices, diag) {
            Err(why) => {
                if degenerate.count < 5 {
                    warnings.push(Warning { loc: p.loc.clone(), msg: format!("skipped degenerate polygon: {why}") });
                }
                degenerate.add(&p.loc, &why);
                if emits {
                    lost_emitters.add(&p.loc, "degenerate");
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
                    if crossing.count < 5 {
                        warnings.push(Warning { loc: p.loc.clone(), msg: "skipped self-intersecting polygon".into() });
                    }
                    crossing.add(&p.loc, "self-intersecting");
                    if emits {
                        lost_emitters.add(&p.loc, "self-intersecting");
                    }
                    continue;
                }
            },
        }
        let two = mats[p.material as usize].two_sided;
        let before = out.len();
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
                    uv: uv.clone(),
                });
            }
            out.push(Polygon { vertices: v, normal, area, material: p.material, object: p.object, back_side: false, two_sided: two, loc: p.loc.clone(), uv: uv.clone() });
        }
        if out.len() == before {
            tiny.add(&p.loc, "too small for the scene's size");
            if emits {
                lost_emitters.add(&p.loc, "too small");
            }
        }
    }
    let skipped = degenerate.count + crossing.count;
    if skipped > 5 {
        warnings.push(Warning { loc: Some(Location::file(&file)), msg: format!("{skipped} degenerate or self-intersecting polygons skipped in all") });
    }
    if split_nonplanar > 0 {
        warnings.push(Warning {
            loc: first_split,
            msg: format!("{split_nonplanar} non-planar polygon(s) split into triangles (v0, vi, vi+1)"),
        });
    }
    drop_duplicates(&mut out, diag, &mut warnings);
    if out.is_empty() {
        let mut why: Vec<String> = Vec::new();
        degenerate.describe(&mut why, "degenerate");
        crossing.describe(&mut why, "self-intersecting");
        // (A reason equal to the heading is not repeated after the location.)
        tiny.describe(&mut why, "too small for the scene's size");
        let msg = if polygons.is_empty() {
            "the scene has no usable polygons: it has no polygons at all".to_string()
        } else {
            format!("the scene has no usable polygons: all {} polygons were skipped: {}", polygons.len(), why.join(", "))
        };
        return Err(Error::input(Location::file(&file), msg));
    }
    let mut lost_light = Vec::new();
    if lost_emitters.count > 0 {
        let n = lost_emitters.count;
        let at = lost_emitters.first.as_ref().map(|l| format!(" (first at {l}: {})", lost_emitters.first_why)).unwrap_or_default();
        lost_light.push(format!("{n} emitting polygon{} {} skipped{at}", if n == 1 { "" } else { "s" }, if n == 1 { "was" } else { "were" }));
    }
    lost_light.extend(ignored_lights);

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
    if let Some(w) = band_edges.windows(2).find(|w| !(w[1] > w[0])) {
        return Err(Error::Invalid(format!("thermal band edges must increase: {} µm then {} µm", w[0], w[1])));
    }
    if let Some(e) = band_edges.iter().find(|e| !(e.is_finite() && **e > 0.0)) {
        return Err(Error::Invalid(format!("thermal band edge {e} µm must be finite and positive")));
    }
    Ok(Scene {
        name,
        materials: mats,
        objects: objs,
        polygons: out,
        camera,
        warnings,
        obstructions,
        file,
        lost_light,
        sky,
        lights,
        textures,
        band_edges,
        node_tree,
    })
}

/// Polygons skipped for one reason: how many, and the first.
#[derive(Default)]
struct Skips {
    count: usize,
    first: Option<Location>,
    first_why: String,
}

impl Skips {
    fn add(&mut self, loc: &Option<Location>, why: &str) {
        if self.count == 0 {
            self.first = loc.clone();
            self.first_why = why.to_string();
        }
        self.count += 1;
    }

    /// "10 degenerate (first at f.obj:7: 2 distinct vertices)".
    fn describe(&self, out: &mut Vec<String>, what: &str) {
        if self.count == 0 {
            return;
        }
        let at = match &self.first {
            Some(l) if self.first_why != what => format!(" (first at {l}: {})", self.first_why),
            Some(l) => format!(" (first at {l})"),
            None => String::new(),
        };
        out.push(format!("{} {what}{at}", self.count));
    }
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
    // The bounding box's diagonal: within √3 of the diameter, in O(n) (the pairwise
    // maximum took minutes on a 500,000-vertex face).
    let (plo, phi) = v.iter().fold((v[0], v[0]), |(l, h), p| (l.min(*p), h.max(*p)));
    let diam = (phi - plo).length();
    if !(area > 1e-12 * diam * diam) || area <= 1e-14 * diag * diag {
        return Err(format!("zero area ({area:e})"));
    }
    let n = nn / nn.length();
    let c = v.iter().copied().sum::<DVec3>() / v.len() as f64;
    let off = v.iter().map(|p| n.dot(*p - c).abs()).fold(0.0, f64::max);
    if v.len() > 3 && off > PLANARITY_TOL * diam {
        return Ok(Cleaned::NonPlanar(v));
    }
    // Drop collinear vertices (turn of ~0 and continuing forward), in one pass.
    let v = drop_collinear(v);
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

/// Removes vertices where the boundary goes straight on, in O(n): a stack pass, then the
/// seam between the last and the first vertices.
fn drop_collinear(v: Vec<DVec3>) -> Vec<DVec3> {
    let straight = |a: DVec3, b: DVec3, d: DVec3| {
        let e1 = b - a;
        let e2 = d - b;
        e1.cross(e2).length() <= 1e-10 * e1.length() * e2.length() && e1.dot(e2) > 0.0
    };
    let mut s: Vec<DVec3> = Vec::with_capacity(v.len());
    for &p in &v {
        while s.len() >= 2 && straight(s[s.len() - 2], s[s.len() - 1], p) {
            s.pop();
        }
        s.push(p);
    }
    let mut first = 0;
    while s.len() - first > 3 {
        let m = s.len();
        if straight(s[m - 2], s[m - 1], s[first]) {
            s.pop();
        } else if straight(s[m - 1], s[first], s[first + 1]) {
            first += 1;
        } else {
            break;
        }
    }
    let s = s.split_off(first.min(s.len()));
    if s.len() < 3 {
        v
    } else {
        s
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
    // Only reflex vertices can lie inside an ear (if any vertex does, a reflex one does),
    // and clipping never makes a convex vertex reflex: test against the first ones.
    let nv = v.len();
    let reflex: Vec<usize> =
        (0..nv).filter(|&i| cross(p2[(i + nv - 1) % nv], p2[i], p2[(i + 1) % nv]) <= 0.0).collect();
    let mut alive = vec![true; nv];
    let mut tris = Vec::new();
    let mut k = 0;
    while idx.len() > 3 {
        let m = idx.len();
        let mut found = false;
        // Resume where the last ear was cut: ears cluster, so this is O(n) per ear at worst
        // and usually O(1).
        for step in 0..m {
            let kk = (k + step) % m;
            let (i0, i1, i2) = (idx[(kk + m - 1) % m], idx[kk], idx[(kk + 1) % m]);
            let (a, b, c) = (p2[i0], p2[i1], p2[i2]);
            if cross(a, b, c) <= 0.0 {
                continue;
            }
            let inside = reflex.iter().any(|&j| {
                if !alive[j] || j == i0 || j == i1 || j == i2 {
                    return false;
                }
                let p = p2[j];
                cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0
            });
            if inside {
                continue;
            }
            tris.push(vec![v[i0], v[i1], v[i2]]);
            idx.remove(kk);
            alive[i1] = false;
            k = if kk == 0 { 0 } else { kk - 1 };
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

/// Checks the lights (finite, non-negative intensity, a finite position, a non-zero
/// direction, cone angles 0 ≤ inner < outer ≤ 90°), normalises their directions and drops
/// the dark ones.
fn validate_lights(lights: Vec<super::Light>, file: &std::path::Path) -> Result<Vec<super::Light>> {
    use super::LightKind;
    let mut out = Vec::with_capacity(lights.len());
    for mut l in lights {
        let at = l.loc.clone().unwrap_or_else(|| Location::file(file));
        let bad = |why: String| Err(Error::input(at.clone(), format!("{}: {why}", l.name)));
        let i = l.intensity.to_array();
        if i.iter().any(|c| !c.is_finite() || *c < 0.0 || *c > MAX_EMISSION) {
            return bad(format!("intensity {i:?} must be finite, non-negative and at most {MAX_EMISSION:e}"));
        }
        let position_ok = |p: DVec3| p.is_finite() && p.abs().max_element() <= MAX_COORDINATE;
        let unit = |d: DVec3| (d.is_finite() && d.length() > 1e-12).then(|| d.normalize());
        match &mut l.kind {
            LightKind::Point { position } => {
                if !position_ok(*position) {
                    return bad(format!("position {:?} must be finite and within ±{MAX_COORDINATE:e}", position.to_array()));
                }
            }
            LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                if !position_ok(*position) {
                    return bad(format!("position {:?} must be finite and within ±{MAX_COORDINATE:e}", position.to_array()));
                }
                let Some(d) = unit(*direction) else {
                    return bad(format!("direction {:?} must be a finite, non-zero vector", direction.to_array()));
                };
                *direction = d;
                let half_pi = std::f64::consts::FRAC_PI_2;
                if !(inner_cone.is_finite() && outer_cone.is_finite() && 0.0 <= *inner_cone && inner_cone < outer_cone && *outer_cone <= half_pi)
                {
                    return bad(format!(
                        "cone angles inner {:.6}° and outer {:.6}° must satisfy 0 ≤ inner < outer ≤ 90°",
                        inner_cone.to_degrees(),
                        outer_cone.to_degrees()
                    ));
                }
            }
            LightKind::Directional { direction } => {
                let Some(d) = unit(*direction) else {
                    return bad(format!("direction {:?} must be a finite, non-zero vector", direction.to_array()));
                };
                *direction = d;
            }
        }
        if l.is_lit() {
            out.push(l);
        }
    }
    Ok(out)
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
                .map(|(i, v)| PolygonDesc { uvs: Vec::new(), vertices: v, material: 0, object: 0, loc: Some(Location::line("t.obj", i + 1)) })
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
    fn reflectance_of_one_is_lowered_or_rejected_when_strict() {
        let mut d = desc(vec![vec![DVec3::ZERO, DVec3::X, DVec3::Y]]);
        d.materials[0].reflectance = Rgb::new(0.5, 1.0, 0.5);
        let s = Scene::from_desc(d.clone()).unwrap();
        assert_eq!(s.materials[0].reflectance, Rgb::new(0.5, MAX_REFLECTANCE, 0.5));
        assert_eq!(s.warnings.iter().filter(|w| w.msg.contains("lowered")).count(), 1);
        d.strict = true;
        let e = Scene::from_desc(d.clone()).unwrap_err();
        assert!(e.to_string().contains("outside [0, 1)"), "{e}");
        d.strict = false;
        d.materials[0].reflectance = Rgb::new(0.5, -0.1, 0.5);
        assert!(Scene::from_desc(d).unwrap_err().to_string().contains("non-negative"));
    }

    #[test]
    fn collinear_vertices_are_dropped_in_one_pass() {
        // A square with extra points on every edge and across the seam (first/last).
        let mut sq = Vec::new();
        for k in 0..4 {
            let (a, b) = [(DVec3::ZERO, DVec3::X), (DVec3::X, DVec3::new(1., 1., 0.)), (DVec3::new(1., 1., 0.), DVec3::Y), (DVec3::Y, DVec3::ZERO)][k];
            for i in 0..5 {
                sq.push(a + (b - a) * (i as f64 / 5.0));
            }
        }
        sq.rotate_left(2); // start in the middle of an edge
        let s = Scene::from_desc(desc(vec![sq])).unwrap();
        assert_eq!(s.polygons.len(), 1);
        assert_eq!(s.polygons[0].vertices.len(), 4);
        assert!((s.polygons[0].area - 1.0).abs() < 1e-12);
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

