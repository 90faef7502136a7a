//! View3D's `.vs3` input (Walton 2002, NISTIR 6925; the NIST View3D program used by
//! EnergyPlus), read as a scene so that existing thermal models run unchanged.
//!
//! Lines start with a one-letter command (case-insensitive); words are separated by
//! blanks, commas or tabs; `!` starts a comment anywhere; `E` ("End of data") or `*` ends
//! the data (anything after it is ignored, as View3D does):
//!
//! - `T title` — the title; `C key=value …` — control values (`encl=1` asks for the
//!   enclosure correction, see [`Vs3Control`]; `eps` is View3D's convergence limit;
//!   `emit=1` asks for emittance-weighted factors; the listing/output keys are accepted and
//!   ignored);
//! - `F 3` (or `G 3`) — 3-D geometry (2-D files, `F 2`, are refused);
//! - `V n x y z` — vertex `n`;
//! - `S n v1 v2 v3 v4 base cmb emit name` — a surface: `v4 = 0` for a triangle; front side
//!   by the right-hand rule; `emit` its emissivity (clamped to [0.001, 0.999] like View3D);
//!   `base > 0` makes it a subsurface lying on surface `base` (a window in a wall: the
//!   base's own area excludes it — its polygon is cut into convex pieces around it);
//!   `cmb > 0` combines it with an earlier surface (one object, one row);
//! - `O n v1 v2 v3 v4 …` — an obstruction-only surface: it blocks but has no row/column
//!   ([`SceneDesc::obstructions`]).
//!
//! Each surface becomes an object with its name (unnamed: `S<n>`). Materials follow the
//! grey-body convention: reflectance `ρ = 1 − ε`, no emission (View3D computes geometry
//! only; temperatures are the solver's business). Every error names the file and line.

use std::collections::HashMap;
use std::path::Path;

use glam::{DVec2, DVec3};

use super::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
use crate::geom::{PieceSet, PlaneFrame};
use crate::{Error, Location, Result, Rgb, Warning};

/// What a `.vs3` file's `T` and `C` lines ask for.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Vs3Control {
    /// The `T` line.
    pub title: String,
    /// `encl=1`: the surfaces form an enclosure; enforce reciprocity and closure.
    pub enclosure: bool,
    /// `eps=`: View3D's convergence limit (a relative tolerance).
    pub eps: Option<f64>,
    /// `emit=1`: write View3D's emittance-weighted factors (Hottel's total exchange factors
    /// `ℱᵢⱼ = εᵢBᵢⱼ`, see [`crate::thermal::total_exchange_factors`]) instead of plain `F`.
    pub emittances: bool,
}

/// Reads a `.vs3` file as a scene.
pub fn load_vs3(path: &Path) -> Result<SceneDesc> {
    Ok(read_vs3(path)?.0)
}

/// Reads a `.vs3` file: the scene and its control values.
pub fn read_vs3(path: &Path) -> Result<(SceneDesc, Vs3Control)> {
    let text = super::obj::read_text(path)?;
    let mut r = parse_vs3(&text, path)?;
    r.0.name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("view3d").to_string();
    Ok(r)
}

struct Surface {
    number: i64,
    verts: Vec<DVec3>,
    base: i64,
    cmb: i64,
    emit: f64,
    name: String,
    obstruction: bool,
    loc: Location,
}

/// Parses `.vs3` text (`path` names the file in errors).
pub fn parse_vs3(text: &str, path: &Path) -> Result<(SceneDesc, Vs3Control)> {
    let mut ctrl = Vs3Control::default();
    let mut warnings = Vec::new();
    let mut verts: HashMap<i64, (DVec3, usize)> = HashMap::new();
    let mut surfaces: Vec<Surface> = Vec::new();
    let mut numbers: HashMap<i64, usize> = HashMap::new();
    let mut saw_geometry = false;
    'lines: for (ln, raw) in super::split_lines(text).enumerate() {
        let lineno = ln + 1;
        let loc = Location::line(path, lineno);
        let line = match raw.find('!') {
            Some(k) => &raw[..k],
            None => raw,
        };
        let words: Vec<&str> = line.split([' ', '\t', ',', '\r']).filter(|w| !w.is_empty()).collect();
        let Some(first) = words.first() else { continue };
        let cmd = first.chars().next().unwrap_or(' ').to_ascii_uppercase();
        let rest = &words[1..];
        let err = |msg: String| Error::input(loc.clone(), msg);
        match cmd {
            '*' | 'E' => break 'lines,
            '/' => continue,
            // The title is the rest of the line after the first word, which starts after the
            // leading separators (not only whitespace: a leading ',' too).
            'T' => ctrl.title = line.trim_start_matches([' ', '\t', ',', '\r'])[first.len()..].trim().to_string(),
            'C' => parse_control(rest, &loc, &mut ctrl, &mut warnings)?,
            'F' | 'G' => {
                saw_geometry = true;
                match rest.first().copied() {
                    Some("3") => {}
                    Some("2") => return Err(err("2-D View3D geometry (F 2) is not supported; only 3-D (F 3)".into())),
                    Some(o) => return Err(err(format!("unknown View3D geometry format '{o}' (expected 3)"))),
                    None => return Err(err("the F line needs the geometry format (3)".into())),
                }
            }
            'V' => {
                if rest.len() < 4 {
                    return Err(err(format!("a V line needs a number and 3 coordinates, found {} words", rest.len())));
                }
                let n = int(rest[0], &loc, "vertex number")?;
                let p = DVec3::new(num(rest[1], &loc, "x")?, num(rest[2], &loc, "y")?, num(rest[3], &loc, "z")?);
                if let Some((_, first)) = verts.insert(n, (p, lineno)) {
                    return Err(err(format!("vertex {n} is defined twice (first on line {first})")));
                }
            }
            'S' | 'O' => {
                let obstruction = cmd == 'O';
                let need = if obstruction { 5 } else { 8 };
                if rest.len() < need {
                    return Err(err(format!(
                        "{} line needs {} (number, 4 vertices{}), found {} words",
                        cmd,
                        need,
                        if obstruction { "" } else { ", base, cmb, emit" },
                        rest.len()
                    )));
                }
                let n = int(rest[0], &loc, "surface number")?;
                let mut vs = Vec::with_capacity(4);
                for (k, w) in rest[1..5].iter().enumerate() {
                    let v = int(w, &loc, "vertex number")?;
                    if v == 0 && k == 3 {
                        continue; // triangle
                    }
                    match verts.get(&v) {
                        Some((p, _)) => vs.push(*p),
                        None => return Err(err(format!("surface {n} uses vertex {v}, which is not defined above"))),
                    }
                }
                let (base, cmb, emit, name) = if obstruction {
                    (0, 0, 0.9, rest.get(8).map(|s| s.to_string()).unwrap_or_else(|| format!("O{n}")))
                } else {
                    let base = int(rest[5], &loc, "base surface")?;
                    let cmb = int(rest[6], &loc, "combine surface")?;
                    let mut emit = num(rest[7], &loc, "emissivity")?;
                    if emit > 0.999 || emit < 0.001 {
                        let c = emit.clamp(0.001, 0.999);
                        warnings.push(Warning {
                            loc: Some(loc.clone()),
                            msg: format!("emissivity {emit} of surface {n} replaced by {c} (View3D's range)"),
                        });
                        emit = c;
                    }
                    (base, cmb, emit, rest.get(8).map(|s| s.to_string()).unwrap_or_else(|| format!("S{n}")))
                };
                if let Some(&k) = numbers.get(&n) {
                    return Err(err(format!("surface {n} is defined twice (first on line {})", surfaces[k].loc.line.unwrap_or(0))));
                }
                for (what, r) in [("base", base), ("combine", cmb)] {
                    if r != 0 && !numbers.contains_key(&r) {
                        return Err(err(format!("surface {n}: {what} surface {r} must be a surface defined above")));
                    }
                }
                numbers.insert(n, surfaces.len());
                surfaces.push(Surface { number: n, verts: vs, base, cmb, emit, name, obstruction, loc });
            }
            _ => return Err(err(format!("unknown View3D line type '{first}' (expected T, C, F, V, S, O, E or !)"))),
        }
    }
    if !saw_geometry {
        warnings.push(Warning { loc: Some(Location::file(path)), msg: "no F line; assuming 3-D geometry (F 3)".into() });
    }
    if surfaces.iter().all(|s| s.obstruction) {
        return Err(Error::input(Location::file(path), "no surfaces (S lines) in the file"));
    }

    // Objects: one per surface, except combined surfaces, which join their target's.
    let mut desc = SceneDesc { name: String::new(), warnings, ..Default::default() };
    let mut object_of = vec![0u32; surfaces.len()];
    for (k, s) in surfaces.iter().enumerate() {
        if s.cmb != 0 {
            let t = numbers[&s.cmb];
            if surfaces[t].cmb != 0 {
                return Err(Error::input(s.loc.clone(), format!("surface {}: combined surfaces cannot be chained", s.number)));
            }
            object_of[k] = object_of[t];
            continue;
        }
        object_of[k] = desc.objects.len() as u32;
        desc.objects.push(ObjectDesc { name: s.name.clone(), loc: Some(s.loc.clone()) });
        if s.obstruction {
            desc.obstructions.push(object_of[k]);
        }
    }
    // Polygons: each surface's own, minus the subsurfaces lying on it.
    for (k, s) in surfaces.iter().enumerate() {
        let material = desc.materials.len() as u32;
        let rho = if s.obstruction { 0.0 } else { 1.0 - s.emit };
        desc.materials.push(MaterialDesc {
            base_texture: None,
            emission_texture: None,
            thermal: None,
            name: s.name.clone(),
            reflectance: Rgb::splat(rho),
            emission: Rgb::ZERO,
            two_sided: None,
            loc: Some(s.loc.clone()),
        });
        let subs: Vec<&Surface> = surfaces.iter().filter(|t| t.base == s.number).collect();
        let pieces = if subs.is_empty() { vec![s.verts.clone()] } else { cut_subsurfaces(s, &subs)? };
        for v in pieces {
            desc.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v, material, object: object_of[k], loc: Some(s.loc.clone()) });
        }
    }
    Ok((desc, ctrl))
}

/// The base surface's polygon with its (coplanar) subsurfaces cut out, as convex pieces in
/// the base's vertex order.
fn cut_subsurfaces(base: &Surface, subs: &[&Surface]) -> Result<Vec<Vec<DVec3>>> {
    let nn = super::newell_normal(&base.verts);
    let area = 0.5 * nn.length();
    if !(area > 0.0) {
        return Err(Error::input(base.loc.clone(), format!("base surface {} has no area", base.number)));
    }
    let n = nn / (2.0 * area);
    let frame = PlaneFrame::new(base.verts[0], n);
    let size = area.sqrt();
    let to2 = |v: &[DVec3]| -> Vec<DVec2> { v.iter().map(|p| frame.to_2d(*p)).collect() };
    let mut set = PieceSet::default();
    set.push(&to2(&base.verts)); // counter-clockwise: the frame's normal is the base's
    let mut next = PieceSet::default();
    let mut tmp = [Vec::new(), Vec::new()];
    for s in subs {
        if s.verts.iter().any(|p| n.dot(*p - base.verts[0]).abs() > 1e-6 * size) {
            return Err(Error::input(
                s.loc.clone(),
                format!("subsurface {} does not lie in the plane of its base surface {}", s.number, base.number),
            ));
        }
        let mut cut = to2(&s.verts);
        if crate::geom::area2_2d(&cut) < 0.0 {
            cut.reverse();
        }
        set.subtract(&cut, 1e-12 * size, 1e-12 * area, &mut next, &mut tmp);
        std::mem::swap(&mut set, &mut next);
    }
    Ok((0..set.len()).map(|k| set.piece(k).iter().map(|q| frame.to_3d(*q)).collect()).collect())
}

fn parse_control(words: &[&str], loc: &Location, ctrl: &mut Vs3Control, warnings: &mut Vec<Warning>) -> Result<()> {
    // Words are `key=value`, or `key = value` split by the separators.
    let mut toks: Vec<&str> = Vec::new();
    for w in words {
        for part in w.split('=') {
            if !part.is_empty() {
                toks.push(part);
            }
        }
    }
    let mut k = 0;
    while k + 1 < toks.len() {
        let (key, val) = (toks[k], toks[k + 1]);
        match key.to_ascii_lowercase().as_str() {
            "encl" => ctrl.enclosure = int(val, loc, "encl")? != 0,
            "eps" => ctrl.eps = Some(num(val, loc, "eps")?),
            "emit" => ctrl.emittances = int(val, loc, "emit")? != 0,
            "list" | "out" | "maxu" | "maxo" | "mino" | "row" | "col" | "prjd" | "maxv" => {
                int(val, loc, key)?;
            }
            _ => warnings.push(Warning { loc: Some(loc.clone()), msg: format!("unknown View3D control word '{key}' ignored") }),
        }
        k += 2;
    }
    if k < toks.len() {
        return Err(Error::input(loc.clone(), format!("control word '{}' has no value", toks[k])));
    }
    Ok(())
}

fn int(w: &str, loc: &Location, what: &str) -> Result<i64> {
    w.parse().map_err(|_| Error::input(loc.clone(), format!("{what}: '{w}' is not an integer")))
}

fn num(w: &str, loc: &Location, what: &str) -> Result<f64> {
    let v: f64 = w.parse().map_err(|_| Error::input(loc.clone(), format!("{what}: '{w}' is not a number")))?;
    if !v.is_finite() {
        return Err(Error::input(loc.clone(), format!("{what}: '{w}' is not a finite number")));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    const PLANES: &str = "T two planes\nC list=1 encl=0 eps=1e-4\nF 3\nV 1 0 0 0\nV 2 1 0 0\nV 3 1 1 0\nV 4 0 1 0\n\
        V 5 0 0 1\nV 6 1 0 1\nV 7 1 1 1\nV 8 0 1 1\nS 1 1 2 3 4 0 0 0.9 bottom ! comment\nS 2 8 7 6 5 0 0 0.5 top\nEnd of data\nS 3 junk\n";

    #[test]
    fn reads_surfaces_and_stops_at_end_of_data() {
        let (d, c) = parse_vs3(PLANES, Path::new("p.vs3")).unwrap();
        assert_eq!(c.title, "two planes");
        assert_eq!(c.eps, Some(1e-4));
        assert!(!c.enclosure);
        assert_eq!(d.objects.len(), 2);
        assert_eq!(d.objects[1].name, "top");
        assert!((d.materials[1].reflectance.x - 0.5).abs() < 1e-15);
        let s = Scene::from_desc(d).unwrap();
        assert!(s.polygons[0].normal.z > 0.99 && s.polygons[1].normal.z < -0.99);
    }

    #[test]
    fn errors_name_file_and_line() {
        let bad = PLANES.replace("S 2 8 7 6 5", "S 2 8 7 6 9");
        let e = parse_vs3(&bad, Path::new("p.vs3")).unwrap_err().to_string();
        assert!(e.starts_with("p.vs3:13:") && e.contains("vertex 9"), "{e}");
        let bad = PLANES.replace("V 3 1 1 0", "V 3 1 x 0");
        let e = parse_vs3(&bad, Path::new("p.vs3")).unwrap_err().to_string();
        assert!(e.starts_with("p.vs3:6:"), "{e}");
        let bad = PLANES.replace("F 3", "F 2");
        assert!(parse_vs3(&bad, Path::new("p.vs3")).unwrap_err().to_string().starts_with("p.vs3:3:"));
    }

    #[test]
    fn subsurface_is_cut_out_of_its_base_and_obstructions_are_marked() {
        let text = "F 3\nV 1 0 0 0\nV 2 4 0 0\nV 3 4 4 0\nV 4 0 4 0\nV 5 1 1 0\nV 6 2 1 0\nV 7 2 2 0\nV 8 1 2 0\n\
            V 9 0 0 1\nV 10 1 0 1\nV 11 1 1 1\nS 1 1 2 3 4 0 0 0.9 wall\nS 2 5 6 7 8 1 0 0.8 window\nS 3 1 2 3 0 0 1 0.9 more\n\
            O 4 9 10 11 0\nE\n";
        let (d, _) = parse_vs3(text, Path::new("w.vs3")).unwrap();
        assert_eq!(d.objects.len(), 3); // wall (+ combined 'more'), window, obstruction
        assert_eq!(d.obstructions, vec![2]);
        let s = Scene::from_desc(d).unwrap();
        let wall: f64 = s.polygons.iter().filter(|p| p.object == 0).map(|p| p.area).sum();
        assert!((wall - (16.0 - 1.0 + 8.0)).abs() < 1e-9, "{wall}");
        assert!(s.is_obstruction(2) && !s.is_obstruction(0));
    }
}
