//! TOML scene files: meshes by reference, plus a camera and per-material overrides.
//!
//! ```toml
//! mesh = "cornell_box.obj"     # relative to this file: .obj, .gltf or .glb;
//!                              # or "builtin:cornell" / "builtin:furnace";
//!                              # or several: meshes = ["room.obj", "lamp.glb"]
//! two_sided = false            # optional: every surface two-sided
//!
//! [camera]                     # optional; or camera = "camera.json" (relative path)
//! position = [278, 273, -800]
//! look_at = [278, 273, 0]
//! up = [0, 1, 0]               # optional, default [0, 1, 0]
//! vfov_deg = 39.3              # full vertical field of view, degrees
//!
//! [materials.light]            # overrides of the mesh's material named `light`
//! emission = [17, 12, 4]       # emitted radiance L_e (linear RGB; exitance is π·L_e)
//! reflectance = [0, 0, 0]      # diffuse reflectance ρ in [0, 1)
//! two_sided = false            # this material's choice wins over the scene's (and over
//!                              # --two-sided): a lamp stays one-sided in a two-sided room
//!
//! # Thermal (`radiosity thermal`; see crate::thermal), per material:
//! # emissivity = 0.8           # hemispherical ε in [0, 1] (default 1 − mean reflectance),
//! #                            # or one per band: emissivity = [0.1, 0.9] (see [thermal])
//! # temperature = 500          # kelvin; or heat_flux = 1000 (W/m² leaving); or adiabatic = true
//! #
//! # [thermal]                  # optional, scene-wide
//! # band_edges = [4.0]         # µm: the spectrum split into bands (here 0–4 µm, 4 µm–∞)
//! #                            # for per-band emissivities (the CLI's --bands overrides)
//!
//! [sky]                        # optional: a uniform sky around the geometry
//! radiance = 1.0               # radiance of every direction that sees no polygon
//!                              # (one value or [r, g, b]; same units as emission)
//! # image = "studio.hdr"       # or an equirectangular environment image (.hdr, .exr;
//! #                            # .png/.jpg as sRGB) of linear radiance by direction, +Y
//! #                            # up (see scene::Environment), instead of `radiance`
//! # strength = 1.0             # multiplies the image's texels
//! # rotation = 0.0             # degrees about +Y (counter-clockwise from above)
//! # portals = [[[0, 3, 0], [4, 3, 0], [4, 3, 2], [0, 3, 2]]]
//! #                            # openings (convex planar polygons) through which the
//! #                            # final gather samples the sky directly (see
//! #                            # scene::Portal): less noise, the same light
//! [sky.sun]                    # optional: a sun (with or without a sky radiance)
//! direction = [0.3, 1, 0.2]    # towards the sun (normalised)
//! irradiance = 1000            # on a surface facing it, unshadowed (exitance units)
//! angular_diameter = 0.53      # degrees, 0 to 20 (default 0.53)
//!
//! [[lights]]                   # optional, any number: point, spot, directional, rect
//! type = "spot"                # "point", "spot", "directional" or "rect"
//! name = "desk lamp"           # optional (default "light N", N from 1 in file order)
//! position = [0, 2.5, 0]       # point, spot
//! direction = [0, -1, 0]       # spot, directional: where the light goes
//! intensity = 40               # point, spot: radiant intensity I, so a surface at r facing
//!                              # it gets I/r²; directional: irradiance on a surface facing
//!                              # it (one value or [r, g, b]; the units of exitance)
//! inner_cone = 20              # spot: degrees of full intensity (default 0)
//! outer_cone = 30              # spot: degrees where it reaches zero (default 45, ≤ 90)
//!
//! [[lights]]                   # an area light: a rectangle that emits from its front,
//! type = "rect"                # the side edge1 × edge2 points to (an emitting polygon of
//! corner = [-0.5, 2.9, -0.5]   # its own material and object, seen by the camera)
//! edge1 = [0, 0, 1]
//! edge2 = [1, 0, 0]
//! radiance = 10                # emitted radiance L_e (one value or [r, g, b])
//! ```
//!
//! Point, spot and directional lights give exact direct light with hard shadows and are
//! not seen by the camera ([`crate::lights`]); glTF files bring theirs (KHR_lights_punctual)
//! with them.
//!
//! Material names that are not bare TOML keys are quoted: `[materials."wall 1"]`. An
//! override applies to every material of that name in every mesh; naming a material that no
//! mesh has is an error that lists the names there are. As in Mitsuba, a key nobody reads
//! is an error (serde `deny_unknown_fields`), so a typo such as `emision` is caught; every
//! error names this file with line and column (the `toml` crate's byte span converted).
//! Values are checked as in the other formats: reflectance finite and ≥ 0, emission
//! finite and ≥ 0 (TOML allows `nan` and `inf`; they are rejected here).
//!
//! The camera given here replaces the mesh's own (a glTF camera); without one the first
//! mesh's camera is used. With several meshes their materials and objects are
//! concatenated in order. A reflectance channel ≥ 1 (here or a glTF mesh's
//! `baseColorFactor`, glTF's default white) is lowered by validation to
//! [`super::MAX_REFLECTANCE`] with a warning (refused in strict mode); an override here sets
//! the value actually wanted. Example: `scenes/cornell-blue-light.toml`.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde::Deserialize;
use toml::Spanned;

use super::{builtin, gltf, obj, Camera, MaterialDesc, SceneDesc};
use crate::{Error, Location, Result, Rgb};

/// The sun's angular diameter when `[sky.sun]` gives none, degrees (the real sun's).
pub const DEFAULT_SUN_DIAMETER_DEG: f64 = 0.53;

/// The prefix that names a built-in scene as a mesh (`mesh = "builtin:cornell"`).
pub const BUILTIN_PREFIX: &str = "builtin:";

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    mesh: Option<Spanned<String>>,
    meshes: Option<Spanned<Vec<Spanned<String>>>>,
    two_sided: Option<bool>,
    camera: Option<Spanned<CameraSpec>>,
    #[serde(default)]
    materials: BTreeMap<String, Spanned<MaterialToml>>,
    sky: Option<Spanned<SkyToml>>,
    #[serde(default)]
    lights: Vec<Spanned<LightToml>>,
    thermal: Option<Spanned<ThermalToml>>,
}

/// `[thermal]`: scene-wide settings of a thermal solve.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ThermalToml {
    /// Wavelengths (µm) that split the spectrum into bands.
    #[serde(default)]
    band_edges: Vec<f64>,
}

/// A material's `emissivity`: one grey value, or one per band.
#[derive(Deserialize)]
#[serde(untagged)]
enum EmissivityToml {
    Grey(f64),
    Bands(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightToml {
    #[serde(rename = "type")]
    kind: Spanned<String>,
    name: Option<String>,
    position: Option<Spanned<[f64; 3]>>,
    direction: Option<Spanned<[f64; 3]>>,
    intensity: Option<Spanned<Radiance>>,
    inner_cone: Option<Spanned<f64>>,
    outer_cone: Option<Spanned<f64>>,
    corner: Option<Spanned<[f64; 3]>>,
    edge1: Option<Spanned<[f64; 3]>>,
    edge2: Option<Spanned<[f64; 3]>>,
    radiance: Option<Spanned<Radiance>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SkyToml {
    radiance: Option<Spanned<Radiance>>,
    image: Option<Spanned<String>>,
    strength: Option<Spanned<f64>>,
    rotation: Option<Spanned<f64>>,
    sun: Option<Spanned<SunToml>>,
    portals: Option<Spanned<Vec<Vec<[f64; 3]>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SunToml {
    direction: Spanned<[f64; 3]>,
    irradiance: Spanned<Radiance>,
    angular_diameter: Option<Spanned<f64>>,
}

/// One value for every channel, or `[r, g, b]`.
#[derive(Deserialize)]
#[serde(untagged)]
enum Radiance {
    Grey(f64),
    Rgb([f64; 3]),
}

impl Radiance {
    /// The value as RGB, finite and non-negative, else an error at its span saying
    /// "`what` [..] must be finite and non-negative".
    fn checked(r: &Spanned<Radiance>, at: &dyn Fn(std::ops::Range<usize>) -> Location, what: &str) -> Result<Rgb> {
        let v = match r.get_ref() {
            Radiance::Grey(g) => [*g; 3],
            Radiance::Rgb(c) => *c,
        };
        if v.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(Error::input(at(r.span()), format!("{what} {v:?} must be finite and non-negative")));
        }
        Ok(Rgb::from_array(v))
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialToml {
    reflectance: Option<Spanned<[f64; 3]>>,
    emission: Option<Spanned<[f64; 3]>>,
    two_sided: Option<bool>,
    emissivity: Option<Spanned<EmissivityToml>>,
    temperature: Option<f64>,
    heat_flux: Option<f64>,
    adiabatic: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraToml {
    position: [f64; 3],
    look_at: [f64; 3],
    #[serde(default = "default_up")]
    up: [f64; 3],
    vfov_deg: f64,
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

/// `camera = "file.json"` or a `[camera]` table.
enum CameraSpec {
    File(String),
    Inline(CameraToml),
}

impl<'de> Deserialize<'de> for CameraSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = CameraSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a camera JSON file name or a table with position, look_at, up, vfov_deg")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> std::result::Result<CameraSpec, E> {
                Ok(CameraSpec::File(s.to_string()))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> std::result::Result<CameraSpec, A::Error> {
                // Keeps the table's own errors (unknown key, wrong type) with their spans.
                CameraToml::deserialize(de::value::MapAccessDeserializer::new(map)).map(CameraSpec::Inline)
            }
        }
        d.deserialize_any(V)
    }
}

/// Line and column (1-based) of byte `offset` in `text`.
fn location(file: &Path, text: &str, offset: usize) -> Location {
    let mut off = offset.min(text.len());
    while !text.is_char_boundary(off) {
        off -= 1;
    }
    let before = &text[..off];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Location { file: file.into(), line: Some(line), column: Some(column) }
}

/// Reads a TOML scene file and the meshes it names.
pub fn load_toml(path: &Path) -> Result<SceneDesc> {
    let text = obj::read_text(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    parse_toml(&text, path, &dir)
}

/// Parses TOML scene text; `file` names it in errors, relative paths are resolved from `dir`.
pub fn parse_toml(text: &str, file: &Path, dir: &Path) -> Result<SceneDesc> {
    let at = |span: std::ops::Range<usize>| location(file, text, span.start);
    let spec: FileToml = toml::from_str(text).map_err(|e| {
        let loc = match e.span() {
            Some(s) => at(s),
            None => Location::file(file),
        };
        Error::input(loc, e.message().trim_end().to_string())
    })?;

    // Meshes.
    let mesh_specs: Vec<Spanned<String>> = match (spec.mesh, spec.meshes) {
        (Some(m), None) => vec![m],
        (None, Some(list)) if !list.get_ref().is_empty() => list.into_inner(),
        (None, Some(list)) => return Err(Error::input(at(list.span()), "`meshes` is empty")),
        (Some(m), Some(_)) => return Err(Error::input(at(m.span()), "give either `mesh` or `meshes`, not both")),
        (None, None) => {
            return Err(Error::input(
                Location::file(file),
                "the scene file names no mesh: add `mesh = \"file.obj\"` (or .gltf, .glb, builtin:cornell)",
            ))
        }
    };
    let mut desc = SceneDesc {
        name: file.file_stem().and_then(|s| s.to_str()).unwrap_or("scene").to_string(),
        ..Default::default()
    };
    // Per merged material: does a glTF baseColorFactor still need its range check?
    let mut from_gltf: Vec<bool> = Vec::new();
    let mut mesh_camera: Option<Camera> = None;
    for m in &mesh_specs {
        let (part, is_gltf) = load_mesh(m.get_ref(), at(m.span()), dir)?;
        let mo = desc.materials.len() as u32;
        let oo = desc.objects.len() as u32;
        from_gltf.extend(std::iter::repeat_n(is_gltf, part.materials.len()));
        // Textures come along, renumbered after those of the meshes before.
        let to = desc.textures.len() as u32;
        desc.materials.extend(part.materials.into_iter().map(|mut m| {
            for t in [&mut m.base_texture, &mut m.emission_texture].into_iter().flatten() {
                t.texture += to;
            }
            m
        }));
        desc.textures.extend(part.textures);
        // A glTF's node tree stays with the scene when it is the only mesh.
        desc.node_tree = if mesh_specs.len() == 1 { part.node_tree } else { None };
        desc.objects.extend(part.objects);
        desc.polygons.extend(part.polygons.into_iter().map(|mut p| {
            p.material += mo;
            p.object += oo;
            p
        }));
        desc.warnings.extend(part.warnings);
        desc.ignored_lights.extend(part.ignored_lights);
        desc.lights.extend(part.lights);
        desc.two_sided |= part.two_sided;
        if mesh_camera.is_none() {
            mesh_camera = part.camera;
        }
    }
    desc.two_sided |= spec.two_sided.unwrap_or(false);

    // Camera.
    desc.camera = match spec.camera {
        None => mesh_camera,
        Some(c) => {
            let loc = at(c.span());
            Some(match c.into_inner() {
                CameraSpec::File(f) => {
                    let p = dir.join(&f);
                    let text = super::read_input(&p)
                        .map_err(|e| Error::input(loc, format!("camera file '{}': {e}", p.display())))?;
                    Camera::from_json_str(&String::from_utf8_lossy(&text), &p)?
                }
                CameraSpec::Inline(t) => {
                    let cam = Camera {
                        position: DVec3::from_array(t.position),
                        look_at: DVec3::from_array(t.look_at),
                        up: DVec3::from_array(t.up),
                        vfov_deg: t.vfov_deg,
                    };
                    cam.validate().map_err(|m| Error::input(loc, format!("camera: {m}")))?;
                    cam
                }
            })
        }
    };

    // Material overrides.
    if let Some(sky) = &spec.sky {
        let rgb = |r: &Spanned<Radiance>, what: &str| Radiance::checked(r, &at, &format!("[sky]: {what}"));
        let radiance = match &sky.get_ref().radiance {
            Some(r) => rgb(r, "radiance")?,
            None => Rgb::ZERO,
        };
        let sun = match &sky.get_ref().sun {
            None => None,
            Some(sun) => {
                let sun = sun.get_ref();
                let d = DVec3::from_array(*sun.direction.get_ref());
                if !d.is_finite() || d.length() < 1e-12 {
                    return Err(Error::input(
                        at(sun.direction.span()),
                        format!("[sky.sun]: direction {:?} must be a finite, non-zero vector towards the sun", d.to_array()),
                    ));
                }
                let diameter = match &sun.angular_diameter {
                    Some(a) if !(0.0..=super::validate::MAX_SUN_DIAMETER_DEG).contains(a.get_ref()) => {
                        return Err(Error::input(
                            at(a.span()),
                            format!(
                                "[sky.sun]: angular_diameter {} must be between 0 and {} degrees",
                                a.get_ref(),
                                super::validate::MAX_SUN_DIAMETER_DEG
                            ),
                        ))
                    }
                    Some(a) => *a.get_ref(),
                    None => DEFAULT_SUN_DIAMETER_DEG,
                };
                Some(super::Sun {
                    direction: d.normalize(),
                    irradiance: rgb(&sun.irradiance, "sun irradiance")?,
                    angular_diameter_deg: diameter,
                })
            }
        };
        let sk = sky.get_ref();
        let environment = match &sk.image {
            None => {
                if let Some(k) = sk.strength.as_ref().or(sk.rotation.as_ref()) {
                    return Err(Error::input(at(k.span()), "[sky]: strength and rotation belong to an image"));
                }
                None
            }
            Some(f) => {
                if let Some(r) = &sk.radiance {
                    return Err(Error::input(at(r.span()), "[sky]: give a radiance or an image, not both"));
                }
                let strength = sk.strength.as_ref().map_or(Ok(1.0), |v| match *v.get_ref() {
                    x if x.is_finite() && x >= 0.0 => Ok(x),
                    x => Err(Error::input(at(v.span()), format!("[sky]: strength {x} must be a finite number ≥ 0"))),
                })?;
                let rotation = sk.rotation.as_ref().map_or(Ok(0.0), |v| match *v.get_ref() {
                    x if x.is_finite() => Ok(x),
                    x => Err(Error::input(at(v.span()), format!("[sky]: rotation {x} must be a finite number of degrees"))),
                })?;
                let path = dir.join(f.get_ref());
                let bytes = super::read_input(&path)
                    .map_err(|e| Error::input(at(f.span()), format!("[sky]: image '{}': {e}", path.display())))?;
                let texture = super::Texture::decode_environment(&path.display().to_string(), &bytes)
                    .map_err(|e| Error::input(at(f.span()), format!("[sky]: image '{}': {e}", path.display())))?;
                Some(super::Environment { texture: std::sync::Arc::new(texture), strength, rotation_deg: rotation })
            }
        };
        if sk.radiance.is_none() && sun.is_none() && environment.is_none() {
            return Err(Error::input(at(sky.span()), "[sky]: give a radiance or an image, a [sky.sun], or both"));
        }
        let mut portals = Vec::new();
        if let Some(list) = &sk.portals {
            if sk.radiance.is_none() && environment.is_none() {
                return Err(Error::input(at(list.span()), "[sky]: portals sample the sky's radiance or image, and this sky has neither"));
            }
            for (k, corners) in list.get_ref().iter().enumerate() {
                let portal = super::Portal::new(corners.iter().map(|c| DVec3::from_array(*c)).collect())
                    .map_err(|e| Error::input(at(list.span()), format!("[sky]: portal {}: {e}", k + 1)))?;
                portals.push(portal);
            }
        }
        desc.sky = Some(super::Sky { radiance, sun, environment, portals });
    }
    if let Some(th) = &spec.thermal {
        let edges = &th.get_ref().band_edges;
        if edges.iter().any(|e| !(e.is_finite() && *e > 0.0)) || edges.windows(2).any(|w| !(w[1] > w[0])) {
            return Err(Error::input(
                at(th.span()),
                format!("[thermal]: band_edges {edges:?} must be positive wavelengths in µm, increasing"),
            ));
        }
        desc.band_edges = edges.clone();
    }

    for (name, ov) in &spec.materials {
        let loc = at(ov.span());
        let ov = ov.get_ref();
        let reflectance = match &ov.reflectance {
            Some(r) => {
                let v = *r.get_ref();
                // ≥ 1 is lowered (or refused in strict mode) by validation, at this table.
                if v.iter().any(|c| !c.is_finite() || *c < 0.0) {
                    return Err(Error::input(
                        at(r.span()),
                        format!("material '{name}': reflectance {v:?} must be finite and non-negative"),
                    ));
                }
                Some(Rgb::from_array(v))
            }
            None => None,
        };
        let emission = match &ov.emission {
            Some(e) => {
                let v = *e.get_ref();
                if v.iter().any(|c| !c.is_finite() || *c < 0.0) {
                    return Err(Error::input(
                        at(e.span()),
                        format!("material '{name}': emitted radiance {v:?} must be finite and non-negative"),
                    ));
                }
                Some(Rgb::from_array(v))
            }
            None => None,
        };
        // Thermal: at most one boundary condition; values checked by validation.
        let given: Vec<super::Boundary> = [
            ov.temperature.map(super::Boundary::Temperature),
            ov.heat_flux.map(super::Boundary::HeatFlux),
            ov.adiabatic.filter(|a| *a).map(|_| super::Boundary::Adiabatic),
        ]
        .into_iter()
        .flatten()
        .collect();
        if given.len() > 1 {
            return Err(Error::input(
                loc,
                format!("[materials.{name}]: give one of temperature, heat_flux and adiabatic = true, not several"),
            ));
        }
        let (emissivity, band_emissivity) = match ov.emissivity.as_ref().map(|e| e.get_ref()) {
            Some(EmissivityToml::Grey(e)) => (Some(*e), Vec::new()),
            Some(EmissivityToml::Bands(b)) => (None, b.clone()),
            None => (None, Vec::new()),
        };
        if let Some(e) = &ov.emissivity {
            if matches!(e.get_ref(), EmissivityToml::Bands(b) if b.len() < 2) {
                return Err(Error::input(
                    at(e.span()),
                    format!("[materials.{name}]: emissivity: give one number (grey), or one per band (at least two)"),
                ));
            }
        }
        let thermal = (ov.emissivity.is_some() || !given.is_empty())
            .then(|| super::ThermalDesc { emissivity, band_emissivity, boundary: given.first().copied() });
        let mut found = false;
        for (i, m) in desc.materials.iter_mut().enumerate().filter(|(_, m)| &m.name == name) {
            found = true;
            apply(m, reflectance, emission, ov.two_sided, &loc);
            if thermal.is_some() {
                m.thermal = thermal.clone();
                m.loc = Some(loc.clone());
            }
            if reflectance.is_some() {
                from_gltf[i] = false;
            }
        }
        if !found {
            let mut names: Vec<&str> = desc.materials.iter().map(|m| m.name.as_str()).collect();
            names.sort_unstable();
            names.dedup();
            return Err(Error::input(
                loc,
                format!("[materials.{name}]: no material of that name in the mesh; its materials are: {}", names.join(", ")),
            ));
        }
    }
    for (k, l) in spec.lights.iter().enumerate() {
        add_light(&mut desc, k, l, &at)?;
    }
    let unchecked: Vec<MaterialDesc> =
        desc.materials.iter().zip(&from_gltf).filter(|(_, g)| **g).map(|(m, _)| m.clone()).collect();
    gltf::check_base_colors(&unchecked, file)?;
    Ok(desc)
}

/// Adds the `k`-th `[[lights]]` table: a [`super::Light`], or for `type = "rect"` an
/// emitting rectangle with a material and an object of its own.
fn add_light(desc: &mut SceneDesc, k: usize, l: &Spanned<LightToml>, at: &dyn Fn(std::ops::Range<usize>) -> Location) -> Result<()> {
    use super::{Light, LightKind, ObjectDesc, PolygonDesc};
    let loc = at(l.span());
    let t = l.get_ref();
    let name = t.name.clone().unwrap_or_else(|| format!("light {}", k + 1));
    let kind = t.kind.get_ref().as_str();
    let err = |span: std::ops::Range<usize>, msg: String| Err(Error::input(at(span), format!("[[lights]] '{name}': {msg}")));
    // Which keys each type reads; any other is an error (as for unknown keys).
    let allowed: &[&str] = match kind {
        "point" => &["position", "intensity"],
        "spot" => &["position", "direction", "intensity", "inner_cone", "outer_cone"],
        "directional" => &["direction", "intensity"],
        "rect" => &["corner", "edge1", "edge2", "radiance"],
        other => {
            return err(t.kind.span(), format!("type \"{other}\" is not one of \"point\", \"spot\", \"directional\", \"rect\""))
        }
    };
    let given: [(&str, Option<std::ops::Range<usize>>); 9] = [
        ("position", t.position.as_ref().map(|v| v.span())),
        ("direction", t.direction.as_ref().map(|v| v.span())),
        ("intensity", t.intensity.as_ref().map(|v| v.span())),
        ("inner_cone", t.inner_cone.as_ref().map(|v| v.span())),
        ("outer_cone", t.outer_cone.as_ref().map(|v| v.span())),
        ("corner", t.corner.as_ref().map(|v| v.span())),
        ("edge1", t.edge1.as_ref().map(|v| v.span())),
        ("edge2", t.edge2.as_ref().map(|v| v.span())),
        ("radiance", t.radiance.as_ref().map(|v| v.span())),
    ];
    for (key, span) in &given {
        if let (Some(span), false) = (span, allowed.contains(key)) {
            return err(span.clone(), format!("`{key}` is not read by a {kind} light (it reads {})", allowed.join(", ")));
        }
    }
    for key in allowed.iter().filter(|k| !["inner_cone", "outer_cone"].contains(k)) {
        if given.iter().any(|(g, s)| g == key && s.is_none()) {
            return err(l.span(), format!("a {kind} light needs `{key}`"));
        }
    }
    let vec3 = |v: &Option<Spanned<[f64; 3]>>, what: &str| -> Result<DVec3> {
        let v = v.as_ref().expect("checked above");
        let d = DVec3::from_array(*v.get_ref());
        if !d.is_finite() {
            return Err(Error::input(at(v.span()), format!("[[lights]] '{name}': {what} {:?} must be finite", d.to_array())));
        }
        Ok(d)
    };
    let rgb = |r: &Option<Spanned<Radiance>>, what: &str| {
        Radiance::checked(r.as_ref().expect("checked above"), at, &format!("[[lights]] '{name}': {what}"))
    };
    let cone = |c: &Option<Spanned<f64>>, default: f64| -> Result<f64> {
        match c {
            None => Ok(default),
            Some(c) if c.get_ref().is_finite() && (0.0..=90.0).contains(c.get_ref()) => Ok(c.get_ref().to_radians()),
            Some(c) => Err(Error::input(at(c.span()), format!("[[lights]] '{name}': cone angle {} must be 0 to 90 degrees", c.get_ref()))),
        }
    };
    let kind = match kind {
        "point" => LightKind::Point { position: vec3(&t.position, "position")? },
        "spot" => {
            let (inner_cone, outer_cone) = (cone(&t.inner_cone, 0.0)?, cone(&t.outer_cone, 45.0)?);
            if inner_cone >= outer_cone {
                let deg = |c: &Option<Spanned<f64>>, d: f64| c.as_ref().map_or(d, |c| *c.get_ref());
                return err(
                    l.span(),
                    format!("inner_cone {}° must be below outer_cone {}°", deg(&t.inner_cone, 0.0), deg(&t.outer_cone, 45.0)),
                );
            }
            LightKind::Spot { position: vec3(&t.position, "position")?, direction: vec3(&t.direction, "direction")?, inner_cone, outer_cone }
        }
        "directional" => LightKind::Directional { direction: vec3(&t.direction, "direction")? },
        _ => {
            // An emitting rectangle.
            let c = vec3(&t.corner, "corner")?;
            let (e1, e2) = (vec3(&t.edge1, "edge1")?, vec3(&t.edge2, "edge2")?);
            if e1.cross(e2).length() <= 1e-12 * e1.length() * e2.length() || e1.length() == 0.0 || e2.length() == 0.0 {
                return err(l.span(), format!("edge1 {:?} and edge2 {:?} span no area", e1.to_array(), e2.to_array()));
            }
            let material = desc.materials.len() as u32;
            desc.materials.push(MaterialDesc {
                base_texture: None,
                emission_texture: None,
                thermal: None,
                name: format!("light:{name}"),
                reflectance: Rgb::ZERO,
                emission: rgb(&t.radiance, "radiance")?,
                two_sided: Some(false),
                loc: Some(loc.clone()),
            });
            let object = desc.objects.len() as u32;
            desc.objects.push(ObjectDesc { name: name.clone(), loc: Some(loc.clone()) });
            desc.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: vec![c, c + e1, c + e1 + e2, c + e2], material, object, loc: Some(loc) });
            return Ok(());
        }
    };
    let intensity = rgb(&t.intensity, "intensity")?;
    desc.lights.push(Light { name, kind, intensity, loc: Some(loc) });
    Ok(())
}

fn apply(m: &mut MaterialDesc, reflectance: Option<Rgb>, emission: Option<Rgb>, two_sided: Option<bool>, loc: &Location) {
    if let Some(r) = reflectance {
        m.reflectance = r;
    }
    if let Some(e) = emission {
        m.emission = e;
    }
    if let Some(t) = two_sided {
        m.two_sided = Some(t);
    }
    if reflectance.is_some() || emission.is_some() {
        // Later errors about this material's values point at the override.
        m.loc = Some(loc.clone());
    }
}

/// Loads one mesh reference; returns it and whether it is glTF.
fn load_mesh(spec: &str, loc: Location, dir: &Path) -> Result<(SceneDesc, bool)> {
    if let Some(name) = spec.strip_prefix(BUILTIN_PREFIX) {
        return match builtin::by_name(name) {
            Some(d) => Ok((d, false)),
            None => Err(Error::input(
                loc,
                format!("'{spec}': no such built-in scene (there are: {})", builtin::NAMES.join(", ")),
            )),
        };
    }
    let path: PathBuf = dir.join(spec);
    if let Err(e) = std::fs::metadata(&path) {
        let why = if e.kind() == std::io::ErrorKind::NotFound { "does not exist".to_string() } else { e.to_string() };
        return Err(Error::input(loc, format!("mesh file '{}' {why}", path.display())));
    }
    if path.is_dir() {
        return Err(Error::input(loc, format!("mesh file '{}' is a directory, not a file", path.display())));
    }
    if !path.is_file() {
        return Err(Error::input(
            loc,
            format!("mesh file '{}' is not a regular file (a device, FIFO or socket); only regular files are read", path.display()),
        ));
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default();
    match ext.as_str() {
        "obj" => Ok((obj::load_obj(&path)?, false)),
        "gltf" | "glb" => Ok((gltf::read_gltf(&path)?, true)),
        other => Err(Error::input(
            loc,
            format!("mesh '{spec}': unknown format '.{other}' (expected .obj, .gltf, .glb or builtin:NAME)"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SceneDesc> {
        parse_toml(text, Path::new("s.toml"), Path::new("."))
    }

    #[test]
    fn builtin_mesh_with_override() {
        let d = parse("mesh = \"builtin:cornell\"\n[materials.light]\nemission = [1, 2, 3]\n").unwrap();
        let light = d.materials.iter().find(|m| m.name == "light").unwrap();
        assert_eq!(light.emission, Rgb::new(1., 2., 3.));
        assert_eq!(light.loc.as_ref().unwrap().line, Some(2));
        assert!(d.camera.is_some());
    }

    #[test]
    fn unknown_keys_name_line_and_column() {
        let e = parse("mesh = \"builtin:cornell\"\n[materials.light]\nemision = [1, 2, 3]\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:1:"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\nfov = 3\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:2:1:"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 1]\nfov = 3\n")
            .unwrap_err();
        assert!(e.to_string().starts_with("s.toml:5:1:"), "{e}");
    }

    #[test]
    fn values_are_checked() {
        let e = parse("mesh = \"builtin:cornell\"\n[materials.light]\nemission = [1, nan, 3]\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:") && e.to_string().contains("finite"), "{e}");
        // Reflectance 1: lowered by validation with a warning at the override's table, refused
        // there in strict mode.
        let mut d = parse("mesh = \"builtin:cornell\"\n[materials.white]\nreflectance = [1, 0.5, 0.5]\n").unwrap();
        let s = crate::scene::Scene::from_desc(d.clone()).unwrap();
        let white = s.materials.iter().find(|m| m.name == "white").unwrap();
        assert_eq!(white.reflectance, Rgb::new(crate::scene::MAX_REFLECTANCE, 0.5, 0.5));
        assert!(s.warnings.iter().any(|w| w.msg.contains("'white' (s.toml:2:")), "{:?}", s.warnings);
        d.strict = true;
        let e = crate::scene::Scene::from_desc(d).unwrap_err();
        assert!(e.to_string().starts_with("s.toml:2:") && e.to_string().contains("[0, 1)"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[materials.white]\nreflectance = [-1, 0.5, 0.5]\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:") && e.to_string().contains("non-negative"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[materials.nope]\nemission = [1, 1, 1]\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:2:") && e.to_string().contains("green, light, red, white"), "{e}");
    }

    #[test]
    fn sky_portals_are_read_and_checked() {
        let d = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = 1\nportals = [[[0, 2, 0], [1, 2, 0], [1, 2, 1], [0, 2, 1]]]\n").unwrap();
        let p = &d.sky.unwrap().portals;
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].vertices().len(), 4);
        assert!((p[0].normal().y.abs() - 1.0).abs() < 1e-12);
        for (bad, why) in [
            ("[[0, 2, 0], [1, 2, 0], [1, 3, 1], [0, 2, 1]]", "off the plane"),
            ("[[0, 2, 0], [1, 2, 0]]", "at least 3"),
            ("[[0, 2, 0], [1, 2, 0], [2, 2, 0]]", "no area"),
            ("[[0, 2, 0], [2, 2, 1], [0, 2, 2], [0.5, 2, 1]]", "not convex"),
            // A star turns the same way at every corner.
            ("[[0, 2, 1], [0.59, 2, -0.81], [-0.95, 2, 0.31], [0.95, 2, 0.31], [-0.59, 2, -0.81]]", "not convex"),
        ] {
            let e = parse(&format!("mesh = \"builtin:cornell\"\n[sky]\nradiance = 1\nportals = [{bad}]\n")).unwrap_err().to_string();
            assert!(e.starts_with("s.toml:4:") && e.contains("portal 1") && e.contains(why), "{bad}: {e}");
        }
        // A sun alone has no sky radiance to sample.
        let e = parse("mesh = \"builtin:cornell\"\n[sky]\nportals = [[[0, 2, 0], [1, 2, 0], [1, 2, 1]]]\n[sky.sun]\ndirection = [0, 1, 0]\nirradiance = 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("neither"), "{e}");
    }

    #[test]
    fn sky_takes_one_radiance_or_three_and_checks_them() {
        let d = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = 1.5\n").unwrap();
        assert_eq!(d.sky, Some(crate::scene::Sky::uniform(Rgb::splat(1.5))));
        let d = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = [0.1, 0.2, 0.3]\n").unwrap();
        assert_eq!(d.sky, Some(crate::scene::Sky::uniform(Rgb::new(0.1, 0.2, 0.3))));
        let d = parse("mesh = \"builtin:cornell\"\n[sky.sun]\ndirection = [0, 2, 0]\nirradiance = 100\n").unwrap();
        let sun = d.sky.clone().unwrap().sun.unwrap();
        assert_eq!((sun.direction, sun.irradiance, sun.angular_diameter_deg), (DVec3::Y, Rgb::splat(100.0), 0.53));
        assert_eq!(d.sky.unwrap().radiance, Rgb::ZERO);
        let e = parse("mesh = \"builtin:cornell\"\n[sky.sun]\ndirection = [0, 0, 0]\nirradiance = 1\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:") && e.to_string().contains("non-zero"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[sky.sun]\ndirection = [0, 1, 0]\nirradiance = 1\nangular_diameter = 90\n")
            .unwrap_err();
        assert!(e.to_string().starts_with("s.toml:5:") && e.to_string().contains("between 0 and 20"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[sky]\n").unwrap_err();
        assert!(e.to_string().contains("give a radiance"), "{e}");
        assert_eq!(parse("mesh = \"builtin:cornell\"\n").unwrap().sky, None);
        let e = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = [1, -2, 3]\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:") && e.to_string().contains("non-negative"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = inf\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:") && e.to_string().contains("finite"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = 1\nsuns = 2\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:4:1:"), "{e}");
        let e = parse("mesh = \"builtin:cornell\"\n[sky]\nradiance = [1, 2]\n").unwrap_err();
        assert!(e.to_string().starts_with("s.toml:3:"), "{e}");
    }

    #[test]
    fn location_counts_characters() {
        let l = location(Path::new("f"), "ab\néé x", 8);
        assert_eq!((l.line, l.column), (Some(2), Some(4)));
    }

    #[test]
    fn lights_tables_give_lights_and_rectangles_and_name_what_is_wrong() {
        use crate::scene::LightKind;
        let base = "mesh = \"builtin:cornell\"\n";
        let d = parse(&format!(
            "{base}[[lights]]\ntype = \"point\"\nposition = [1, 2, 3]\nintensity = [1, 2, 3]\n\
             [[lights]]\ntype = \"spot\"\nname = \"s\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nintensity = 2\nouter_cone = 30\n\
             [[lights]]\ntype = \"directional\"\ndirection = [0, -1, 0]\nintensity = 5\n\
             [[lights]]\ntype = \"rect\"\ncorner = [0, 1, 0]\nedge1 = [1, 0, 0]\nedge2 = [0, 0, 1]\nradiance = 4\n"
        ))
        .unwrap();
        assert_eq!(d.lights.len(), 3);
        assert_eq!(d.lights[0].name, "light 1");
        assert_eq!(d.lights[0].kind, LightKind::Point { position: DVec3::new(1.0, 2.0, 3.0) });
        assert_eq!(d.lights[0].intensity, Rgb::new(1.0, 2.0, 3.0));
        assert_eq!(d.lights[0].loc.as_ref().unwrap().line, Some(2));
        let LightKind::Spot { inner_cone, outer_cone, .. } = d.lights[1].kind else { panic!() };
        assert_eq!((inner_cone, outer_cone), (0.0, 30f64.to_radians()));
        let rect = d.polygons.last().unwrap();
        assert_eq!(d.objects[rect.object as usize].name, "light 4");
        let m = &d.materials[rect.material as usize];
        assert_eq!((m.name.as_str(), m.emission, m.reflectance, m.two_sided), ("light:light 4", Rgb::splat(4.0), Rgb::ZERO, Some(false)));
        for (text, want) in [
            ("[[lights]]\ntype = \"area\"\n", "3:8: [[lights]] 'light 1': type \"area\" is not one of"),
            ("[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\n", "a point light needs `intensity`"),
            ("[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, 1, 0]\n", "6:13: [[lights]] 'light 1': `direction` is not read by a point light"),
            ("[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = -1\n", "5:13: [[lights]] 'light 1': intensity [-1.0, -1.0, -1.0] must be finite and non-negative"),
            ("[[lights]]\ntype = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nintensity = 1\nouter_cone = 95\n", "cone angle 95 must be 0 to 90 degrees"),
            ("[[lights]]\ntype = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nintensity = 1\ninner_cone = 40\nouter_cone = 30\n", "inner_cone 40° must be below outer_cone 30°"),
            ("[[lights]]\ntype = \"rect\"\ncorner = [0, 1, 0]\nedge1 = [1, 0, 0]\nedge2 = [2, 0, 0]\nradiance = 1\n", "span no area"),
            ("[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = 1\ncolour = 1\n", "unknown field `colour`"),
        ] {
            let e = parse(&format!("{base}{text}")).unwrap_err().to_string();
            assert!(e.contains(want), "{text}: {e}");
        }
    }
}
