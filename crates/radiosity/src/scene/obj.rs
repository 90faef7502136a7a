//! Wavefront OBJ + MTL reader.
//!
//! Faces keep all their vertices (an n-gon stays one polygon; validation splits it only if
//! it is not planar). `o` and `g` each start a new object (the unit of the report); MTL
//! `Kd` is diffuse reflectance and `Ke` emitted radiance (PRODUCT.md). `map_Kd` and
//! `map_Ke` (PNG or JPEG, relative to the MTL file; options `-o` offset, `-s` scale and
//! `-clamp on` are read, the others skipped) multiply them, read through the faces' `vt`
//! coordinates (v flipped: OBJ's v runs up the image); a map without a `Kd`/`Ke` line
//! multiplies 1. Every error names the file and line. Written by hand rather than with `tobj` because tobj's errors carry
//! no line numbers and it accepts NaN coordinates silently.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use std::sync::Arc;

use glam::{DVec2, DVec3};

use super::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc, Texture, TextureRef, Wrap};
use crate::{Error, Location, Result, Rgb, Warning};

/// Reflectance given to faces that have no `usemtl`.
pub const DEFAULT_REFLECTANCE: f64 = 0.5;

/// Reads an OBJ file and the MTL files it names (relative to the OBJ's folder).
pub fn load_obj(path: &Path) -> Result<SceneDesc> {
    let text = read_text(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut textures: Vec<Arc<Texture>> = Vec::new();
    let mut by_path: HashMap<PathBuf, u32> = HashMap::new();
    let mut desc = parse_obj(&text, path, |name, loc| {
        let p: PathBuf = dir.join(name);
        let t = super::read_input(&p).map_err(|e| {
            Error::input(loc.clone(), format!("cannot read material library '{}': {e}", p.display()))
        })?;
        let (mut mats, maps) = parse_mtl_maps(&String::from_utf8_lossy(&t), &p)?;
        // Decode each map once; the materials' references become scene texture indices.
        let mdir = p.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut index = Vec::with_capacity(maps.len());
        for (file, mloc) in maps {
            let tp = mdir.join(&file);
            if let Some(&k) = by_path.get(&tp) {
                index.push(k);
                continue;
            }
            let bytes = super::read_input(&tp)
                .map_err(|e| Error::input(mloc.clone(), format!("cannot read texture '{}': {e}", tp.display())))?;
            let tex = Texture::decode(&tp.display().to_string(), &bytes)
                .map_err(|e| Error::input(mloc.clone(), format!("texture '{}' {e}", tp.display())))?;
            let k = textures.len() as u32;
            textures.push(Arc::new(tex));
            by_path.insert(tp, k);
            index.push(k);
        }
        for m in &mut mats {
            for t in [&mut m.base_texture, &mut m.emission_texture].into_iter().flatten() {
                t.texture = index[t.texture as usize];
            }
        }
        Ok(mats)
    })?;
    desc.textures = textures;
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
    let mut texcoords: Vec<DVec2> = Vec::new();
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
            "vt" => {
                let vals: Vec<&str> = toks.collect();
                let u = parse_f64(vals.first().copied().unwrap_or(""), &loc, "texture coordinate u")?;
                let v = match vals.get(1) {
                    Some(t) => parse_f64(t, &loc, "texture coordinate v")?,
                    None => 0.0,
                };
                texcoords.push(DVec2::new(u, 1.0 - v));
            }
            "vn" | "vp" | "s" | "mg" | "shadow_obj" | "trace_obj" => {}
            "f" | "fo" => {
                let mut verts = Vec::new();
                let mut uv: Vec<DVec2> = Vec::new();
                let mut all_uv = true;
                for t in toks {
                    let mut parts = t.split('/');
                    let first = parts.next().unwrap_or("");
                    match parts.next().filter(|s| !s.is_empty()) {
                        Some(ts) if all_uv => {
                            let i: i64 = ts.parse().map_err(|_| {
                                Error::input(loc.clone(), format!("face vertex '{t}': texture index '{ts}' is not an index"))
                            })?;
                            let n = texcoords.len() as i64;
                            let idx = if i > 0 { i - 1 } else { n + i };
                            if i == 0 || idx < 0 || idx >= n {
                                // Texture coordinates are optional for light: warn, keep the face.
                                if warned.insert("vt-range".into()) {
                                    desc.warnings.push(Warning {
                                        loc: Some(loc.clone()),
                                        msg: format!(
                                            "face texture index {i} is out of range (there are {n} vt so far); such \
                                             faces are read without texture coordinates"
                                        ),
                                    });
                                }
                                all_uv = false;
                            } else {
                                uv.push(texcoords[idx as usize]);
                            }
                        }
                        _ => all_uv = false,
                    }
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
                let uvs = if all_uv && uv.len() == verts.len() { vec![uv] } else { Vec::new() };
                desc.polygons.push(PolygonDesc { uvs, vertices: verts, material, object, loc: Some(loc) });
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

/// Parses MTL text into materials (`Kd` reflectance, `Ke` emitted radiance); texture maps
/// are dropped (see [`parse_mtl_maps`]).
pub fn parse_mtl(text: &str, file: &Path) -> Result<Vec<MaterialDesc>> {
    let (mut mats, _) = parse_mtl_maps(text, file)?;
    for m in &mut mats {
        m.base_texture = None;
        m.emission_texture = None;
    }
    Ok(mats)
}

/// A texture map's file name (relative to its MTL file) and where it was named.
pub type MapFile = (String, Location);

/// A `map_Kd`/`map_Ke` statement: the image's file name (relative to the MTL) and a
/// reference whose `texture` indexes the returned list of maps.
fn parse_map(rest: &[&str], loc: &Location, maps: &mut Vec<MapFile>) -> Result<TextureRef> {
    let (mut offset, mut scale, mut clamp) = ([0.0; 2], [1.0; 2], false);
    let mut i = 0;
    let num = |k: usize| -> Result<f64> { parse_f64(rest.get(k).copied().unwrap_or(""), loc, "texture map option") };
    while i < rest.len() && rest[i].starts_with('-') && rest.len() - i > 1 {
        // Options take up to three numbers (u v w); read what is numeric.
        let opt = rest[i];
        let nums = rest[i + 1..].iter().take(3).take_while(|t| t.parse::<f64>().is_ok()).count();
        match opt {
            "-o" | "-s" => {
                let u = num(i + 1)?;
                let v = if nums >= 2 { num(i + 2)? } else { if opt == "-s" { 1.0 } else { 0.0 } };
                if opt == "-o" {
                    offset = [u, v];
                } else {
                    scale = [u, v];
                }
                i += 1 + nums;
            }
            "-clamp" => {
                clamp = rest[i + 1] == "on";
                i += 2;
            }
            "-blendu" | "-blendv" | "-cc" | "-imfchan" | "-type" | "-texres" | "-boost" | "-bm" => i += 2,
            "-mm" => i += 1 + nums.min(2),
            "-t" => i += 1 + nums,
            _ => i += 1,
        }
    }
    if i >= rest.len() {
        return Err(Error::input(loc.clone(), "texture map needs a file name"));
    }
    let name = rest[i..].join(" ");
    maps.push((name, loc.clone()));
    // OBJ's v runs up: the reader flips v (v' = 1 − v), so an offset or scale in v acts
    // about the flipped axis: v_obj' = s·v_obj + o  ⇒  v' = s·v' + (1 − s − o).
    let mut r = TextureRef::new((maps.len() - 1) as u32, 0).with_transform([offset[0], 1.0 - scale[1] - offset[1]], 0.0, scale);
    if clamp {
        r.wrap = [Wrap::ClampToEdge; 2];
    }
    Ok(r)
}

/// Parses MTL text into materials and the texture maps they use (file name relative to the
/// MTL file, and where it was named); each material's [`TextureRef::texture`] indexes
/// that list.
pub fn parse_mtl_maps(text: &str, file: &Path) -> Result<(Vec<MaterialDesc>, Vec<MapFile>)> {
    let mut mats: Vec<MaterialDesc> = Vec::new();
    let mut maps: Vec<MapFile> = Vec::new();
    // Kd/Ke lines seen per material (a map without one multiplies 1).
    let mut has_kd: Vec<bool> = Vec::new();
    let mut has_ke: Vec<bool> = Vec::new();
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
            has_kd.push(false);
            has_ke.push(false);
            mats.push(MaterialDesc {
                base_texture: None,
                emission_texture: None,
                thermal: None,
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
                    has_kd[mats.len() - 1] = true;
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
                    has_ke[mats.len() - 1] = true;
                }
            }
            "map_Kd" | "map_Ke" => {
                let Some(m) = mats.last_mut() else {
                    return Err(Error::input(loc, format!("{kw} before any newmtl")));
                };
                let r = parse_map(&rest, &loc, &mut maps)?;
                if kw == "map_Kd" {
                    m.base_texture = Some(r);
                } else {
                    m.emission_texture = Some(r);
                }
            }
            // Other maps (specular, bump, alpha ...) do not change diffuse light.
            k if k.starts_with("map_") || matches!(k, "bump" | "disp" | "decal" | "refl" | "norm") => {}
            "Ka" | "Ks" | "Kt" | "Tf" | "Ns" | "Ni" | "d" | "Tr" | "illum" | "sharpness" | "Pr" | "Pm" | "Ps"
            | "Pc" | "Pcr" | "aniso" | "anisor" => {}
            _ => {}
        }
    }
    for (k, m) in mats.iter_mut().enumerate() {
        if m.base_texture.is_some() && !has_kd[k] {
            m.reflectance = Rgb::ONE;
        }
        if m.emission_texture.is_some() && !has_ke[k] {
            m.emission = Rgb::ONE;
        }
    }
    Ok((mats, maps))
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
