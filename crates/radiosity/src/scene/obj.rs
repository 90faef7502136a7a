//! Wavefront OBJ + MTL reader.
//!
//! Faces keep all their vertices (an n-gon stays one polygon; validation splits it only if
//! it is not planar). `o` and `g` each start a new object (the unit of the report); MTL
//! `Kd` is diffuse reflectance and `Ke` emitted radiance (PRODUCT.md). Every error names
//! the file and line. Written by hand rather than with `tobj` because tobj's errors carry
//! no line numbers and it accepts NaN coordinates silently.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
use crate::{Error, Location, Result, Rgb, Warning};

/// Reflectance given to faces that have no `usemtl`.
pub const DEFAULT_REFLECTANCE: f64 = 0.5;

/// Reads an OBJ file and the MTL files it names (relative to the OBJ's folder).
pub fn load_obj(path: &Path) -> Result<SceneDesc> {
    let text = read_text(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut desc = parse_obj(&text, path, |name, loc| {
        let p: PathBuf = dir.join(name);
        let t = super::read_input(&p).map_err(|e| {
            Error::input(loc.clone(), format!("cannot read material library '{}': {e}", p.display()))
        })?;
        parse_mtl(&String::from_utf8_lossy(&t), &p)
    })?;
    desc.name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene").to_string();
    Ok(desc)
}

/// Reads a whole input file as UTF-8 (lossy: OBJ files in the wild contain Latin-1
/// comments); regular files only, with a size cap ([`super::read_input`]).
pub(crate) fn read_text(path: &Path) -> Result<String> {
    super::read_input_text(path)
}

/// Logical lines: `\` at the end of a line continues it. Yields (1-based line, text). Lines
/// end at `\n`, `\r\n` or a lone `\r` (old Mac files).
fn logical_lines(text: &str) -> impl Iterator<Item = (usize, String)> + '_ {
    let mut lines = super::split_lines(text).enumerate();
    std::iter::from_fn(move || {
        let (i, first) = lines.next()?;
        let mut s = first.to_string();
        while s.ends_with('\\') {
            s.pop();
            match lines.next() {
                Some((_, more)) => {
                    s.push(' ');
                    s.push_str(more)
                }
                None => break,
            }
        }
        Some((i + 1, s))
    })
}

fn strip_comment(s: &str) -> &str {
    match s.find('#') {
        Some(i) => &s[..i],
        None => s,
    }
}

fn parse_f64(tok: &str, loc: &Location, what: &str) -> Result<f64> {
    let v: f64 = tok.parse().map_err(|_| Error::input(loc.clone(), format!("{what}: '{tok}' is not a number")))?;
    if !v.is_finite() {
        return Err(Error::input(loc.clone(), format!("{what}: '{tok}' is not a finite number")));
    }
    Ok(v)
}

/// Parses OBJ text. `load_mtl(name, loc)` supplies the materials of an `mtllib` statement.
pub fn parse_obj(
    text: &str,
    file: &Path,
    mut load_mtl: impl FnMut(&str, &Location) -> Result<Vec<MaterialDesc>>,
) -> Result<SceneDesc> {
    let mut desc = SceneDesc {
        name: file.file_stem().and_then(|s| s.to_str()).unwrap_or("scene").to_string(),
        ..Default::default()
    };
    let mut positions: Vec<DVec3> = Vec::new();
    let mut mat_index: HashMap<String, u32> = HashMap::new();
    let mut current_mat: Option<u32> = None;
    let mut default_mat: Option<u32> = None;
    let mut pending_name: Option<(String, Location)> = None;
    let mut current_obj: Option<u32> = None;
    let mut warned: HashSet<String> = HashSet::new();
    let default_obj_name = desc.name.clone();

    for (lineno, raw) in logical_lines(text) {
        let line = strip_comment(&raw);
        let mut toks = line.split_whitespace();
        let Some(kw) = toks.next() else { continue };
        let loc = Location::line(file, lineno);
        match kw {
            "v" => {
                let vals: Vec<&str> = toks.collect();
                if vals.len() < 3 {
                    return Err(Error::input(loc, format!("vertex needs 3 coordinates, found {}", vals.len())));
                }
                let x = parse_f64(vals[0], &loc, "vertex x")?;
                let y = parse_f64(vals[1], &loc, "vertex y")?;
                let z = parse_f64(vals[2], &loc, "vertex z")?;
                let p = DVec3::new(x, y, z);
                if p.abs().max_element() > super::MAX_COORDINATE {
                    return Err(Error::input(
                        loc,
                        format!(
                            "vertex {:?} has a coordinate of magnitude above {:e}, where areas and squared distances \
                             overflow; rescale the scene",
                            p.to_array(),
                            super::MAX_COORDINATE
                        ),
                    ));
                }
                positions.push(p);
            }
            "vt" | "vn" | "vp" | "s" | "mg" | "shadow_obj" | "trace_obj" => {}
            "f" | "fo" => {
                let mut verts = Vec::new();
                for t in toks {
                    let first = t.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| Error::input(loc.clone(), format!("face vertex '{t}' is not an index")))?;
                    let n = positions.len() as i64;
                    let idx = if i > 0 { i - 1 } else { n + i };
                    if i == 0 || idx < 0 || idx >= n {
                        return Err(Error::input(
                            loc.clone(),
                            format!("face vertex index {i} is out of range (there are {n} vertices so far)"),
                        ));
                    }
                    verts.push(positions[idx as usize]);
                }
                if verts.len() < 3 {
                    return Err(Error::input(loc, format!("face needs at least 3 vertices, found {}", verts.len())));
                }
                let material = match current_mat {
                    Some(m) => m,
                    None => *default_mat.get_or_insert_with(|| {
                        desc.warnings.push(Warning {
                            loc: Some(loc.clone()),
                            msg: format!("faces without 'usemtl' get a grey material (reflectance {DEFAULT_REFLECTANCE})"),
                        });
                        desc.materials.push(MaterialDesc::diffuse("default", Rgb::splat(DEFAULT_REFLECTANCE)));
                        (desc.materials.len() - 1) as u32
                    }),
                };
                if let Some((name, oloc)) = pending_name.take() {
                    desc.objects.push(ObjectDesc { name, loc: Some(oloc) });
                    current_obj = Some((desc.objects.len() - 1) as u32);
                }
                let object = *current_obj.get_or_insert_with(|| {
                    desc.objects.push(ObjectDesc { name: default_obj_name.clone(), loc: Some(loc.clone()) });
                    (desc.objects.len() - 1) as u32
                });
                desc.polygons.push(PolygonDesc { vertices: verts, material, object, loc: Some(loc) });
            }
            "o" | "g" => {
                let name = toks.collect::<Vec<_>>().join(" ");
                let name = if name.is_empty() { default_obj_name.clone() } else { name };
                pending_name = Some((name, loc));
            }
            "usemtl" => {
                let name = toks.collect::<Vec<_>>().join(" ");
                match mat_index.get(&name) {
                    Some(&m) => current_mat = Some(m),
                    None => {
                        return Err(Error::input(
                            loc,
                            format!("usemtl '{name}': no such material in the material libraries read so far"),
                        ))
                    }
                }
            }
            "mtllib" => {
                let names: Vec<&str> = toks.collect();
                if names.is_empty() {
                    return Err(Error::input(loc, "mtllib needs a file name"));
                }
                // File names may contain spaces; try the whole remainder first.
                let joined = names.join(" ");
                let list: Vec<String> =
                    if names.len() > 1 { vec![joined] } else { names.iter().map(|s| s.to_string()).collect() };
                for n in list {
                    for m in load_mtl(&n, &loc)? {
                        let idx = desc.materials.len() as u32;
                        mat_index.insert(m.name.clone(), idx);
                        desc.materials.push(m);
                    }
                }
            }
            "l" | "p" | "curv" | "curv2" | "surf" | "cstype" | "deg" | "bmat" | "step" | "parm" | "trim" | "hole"
            | "scrv" | "sp" | "end" | "con" | "lod" | "usemap" | "maplib" | "bevel" | "c_interp" | "d_interp"
            | "ctech" | "stech" => {
                if warned.insert(kw.to_string()) {
                    desc.warnings.push(Warning {
                        loc: Some(loc),
                        msg: format!("'{kw}' statements (no area to light) are ignored"),
                    });
                }
            }
            other => {
                if warned.insert(other.to_string()) {
                    desc.warnings.push(Warning { loc: Some(loc), msg: format!("unknown statement '{other}' ignored") });
                }
            }
        }
    }
    if desc.polygons.is_empty() {
        return Err(Error::input(Location::file(file), "the file contains no faces"));
    }
    Ok(desc)
}

/// Parses MTL text into materials (`Kd` reflectance, `Ke` emitted radiance).
pub fn parse_mtl(text: &str, file: &Path) -> Result<Vec<MaterialDesc>> {
    let mut mats: Vec<MaterialDesc> = Vec::new();
    let mut warned_tex = false;
    for (lineno, raw) in logical_lines(text) {
        let line = strip_comment(&raw);
        let mut toks = line.split_whitespace();
        let Some(kw) = toks.next() else { continue };
        let loc = Location::line(file, lineno);
        let rest: Vec<&str> = toks.collect();
        if kw == "newmtl" {
            if rest.is_empty() {
                return Err(Error::input(loc, "newmtl needs a name"));
            }
            mats.push(MaterialDesc {
                name: rest.join(" "),
                reflectance: Rgb::ZERO,
                emission: Rgb::ZERO,
                two_sided: None,
                loc: Some(loc),
            });
            continue;
        }
        let color = |what: &str| -> Result<Rgb> {
            if rest.first().is_some_and(|t| *t == "spectral" || *t == "xyz") {
                return Err(Error::input(loc.clone(), format!("{what} {}: only RGB colours are supported", rest[0])));
            }
            match rest.len() {
                1 => Ok(Rgb::splat(parse_f64(rest[0], &loc, what)?)),
                3 => Ok(Rgb::new(
                    parse_f64(rest[0], &loc, what)?,
                    parse_f64(rest[1], &loc, what)?,
                    parse_f64(rest[2], &loc, what)?,
                )),
                n => Err(Error::input(loc.clone(), format!("{what} needs 1 or 3 numbers, found {n}"))),
            }
        };
        match kw {
            "Kd" | "Ke" => {
                let c = color(kw)?;
                let Some(m) = mats.last_mut() else {
                    return Err(Error::input(loc, format!("{kw} before any newmtl")));
                };
                if kw == "Kd" {
                    // Kd ≥ 1 is lowered (or refused in strict mode) by validation.
                    if c.to_array().iter().any(|x| *x < 0.0) {
                        return Err(Error::input(
                            loc,
                            format!("material '{}': Kd {:?} must be non-negative", m.name, c.to_array()),
                        ));
                    }
                    m.reflectance = c;
                    m.loc = Some(loc);
                } else {
                    if c.to_array().iter().any(|x| *x < 0.0) {
                        return Err(Error::input(
                            loc,
                            format!("material '{}': Ke {:?} must be non-negative", m.name, c.to_array()),
                        ));
                    }
                    if c.max_element() > super::MAX_EMISSION {
                        return Err(Error::input(
                            loc,
                            format!(
                                "material '{}': Ke {:?} is above {:e}, where emitted power would overflow; rescale it",
                                m.name,
                                c.to_array(),
                                super::MAX_EMISSION
                            ),
                        ));
                    }
                    m.emission = c;
                }
            }
            k if k.starts_with("map_") || matches!(k, "bump" | "disp" | "decal" | "refl" | "norm") => {
                if !warned_tex {
                    warned_tex = true; // textures: constant colours only for now
                }
            }
            "Ka" | "Ks" | "Kt" | "Tf" | "Ns" | "Ni" | "d" | "Tr" | "illum" | "sharpness" | "Pr" | "Pm" | "Ps"
            | "Pc" | "Pcr" | "aniso" | "anisor" => {}
            _ => {}
        }
    }
    Ok(mats)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SceneDesc> {
        parse_obj(text, Path::new("t.obj"), |_, _| parse_mtl("newmtl w\nKd 0.5 0.5 0.5\nnewmtl l\nKe 1 2 3\n", Path::new("t.mtl")))
    }

    #[test]
    fn reads_quads_objects_and_materials() {
        let d = parse("mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\no a\nusemtl w\nf 1 2 3 4\ng b\nusemtl l\nf -4/1 -3/2/3 -2//1\n").unwrap();
        assert_eq!(d.polygons.len(), 2);
        assert_eq!(d.polygons[0].vertices.len(), 4);
        assert_eq!(d.objects.len(), 2);
        assert_eq!(d.objects[1].name, "b");
        assert_eq!(d.materials[d.polygons[1].material as usize].emission, Rgb::new(1., 2., 3.));
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = parse("v 0 0 0\nv 1 0 0\nv 0 nan 0\n").unwrap_err();
        assert!(e.to_string().starts_with("t.obj:3:"), "{e}");
        let e = parse("v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap_err();
        assert!(e.to_string().starts_with("t.obj:3:") && e.to_string().contains("out of range"), "{e}");
        let e = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl nope\nf 1 2 3\n").unwrap_err();
        assert!(e.to_string().starts_with("t.obj:4:"), "{e}");
        let e = parse("v 0 0\n").unwrap_err();
        assert!(e.to_string().starts_with("t.obj:1:"), "{e}");
    }

    #[test]
    fn mtl_keeps_reflectance_of_one_for_validation_and_rejects_negative() {
        let m = parse_mtl("newmtl a\nKd 1 0.5 0.5\n", Path::new("m.mtl")).unwrap();
        assert_eq!(m[0].reflectance, Rgb::new(1.0, 0.5, 0.5));
        assert_eq!(m[0].loc, Some(Location::line("m.mtl", 2)));
        let e = parse_mtl("newmtl a\nKd -1 0.5 0.5\n", Path::new("m.mtl")).unwrap_err();
        assert!(e.to_string().starts_with("m.mtl:2:"), "{e}");
        let e = parse_mtl("Kd 0.5\n", Path::new("m.mtl")).unwrap_err();
        assert!(e.to_string().contains("before any newmtl"), "{e}");
    }
}
