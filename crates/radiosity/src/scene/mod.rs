//! Stage 1 of the pipeline: scenes.
//!
//! A scene file is read into a [`SceneDesc`] (plain description data: polygons as vertex
//! lists, materials, named objects, an optional camera, each with the place in the file it
//! came from). [`Scene::from_desc`] validates it into a [`Scene`]: non-physical values
//! (negative or non-finite reflectance, negative, non-finite or huge emission — above
//! [`MAX_EMISSION`] —, NaN coordinates or coordinates beyond [`MAX_COORDINATE`]) are errors
//! naming file and line; a reflectance channel ≥ 1 (glTF's default white) is lowered to
//! [`MAX_REFLECTANCE`] with one warning, or refused with [`SceneDesc::strict`];
//! polygons with more than [`MAX_POLYGON_VERTICES`] vertices are refused; degenerate polygons are skipped with a warning; non-planar polygons
//! are split into triangles the way path tracers do (v0,vi,vi+1); concave polygons are
//! triangulated by ear clipping; two-sided materials get a back-facing copy of each polygon
//! (radiosity is per side).
//!
//! Formats: OBJ + MTL ([`obj`]), glTF 2.0 ([`gltf`]), a TOML scene file ([`toml_file`]),
//! and the built-in scenes ([`builtin`]).

pub mod arrays;
pub mod builtin;
pub mod camera;
pub mod gltf;
pub mod obj;
pub mod texture;
pub mod toml_file;
mod validate;
pub use validate::MAX_SUN_DIAMETER_DEG;
pub mod vs3;

use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DVec2, DVec3};

pub use camera::Camera;
pub use texture::{Texture, TextureRef, UvMap, Wrap};
pub use validate::PLANARITY_TOL;
pub use crate::geom::newell_normal;

use crate::{Error, Location, Result, Rgb, Warning};

/// Largest input file read (scene, material library, buffer, camera): 4 GiB. Larger files,
/// and anything that is not a regular file (a directory, a FIFO, `/dev/zero`), are refused
/// before reading.
pub const MAX_INPUT_BYTES: u64 = 4 << 30;

/// Highest diffuse reflectance used: an input channel ≥ 1 (glTF's default `baseColorFactor`
/// 1.0, an OBJ `Kd 1`) is lowered to this, with one warning, unless [`SceneDesc::strict`].
pub const MAX_REFLECTANCE: f64 = 0.95;

/// Largest emitted radiance per channel (`Ke`, `emissiveFactor` × strength): above it,
/// exitance × area or the solution can overflow to infinity.
pub const MAX_EMISSION: f64 = 1e30;

/// Largest coordinate magnitude (vertices, cameras): beyond it areas and squared distances
/// can overflow.
pub const MAX_COORDINATE: f64 = 1e30;

/// Most vertices one polygon may have (OBJ faces); a larger polygon is refused with its
/// file and line (triangulating and meshing it would take minutes).
pub const MAX_POLYGON_VERTICES: usize = 10_000;

/// Reads an input file whole: only regular files (not a directory, FIFO or device such as
/// `/dev/zero`) of at most [`MAX_INPUT_BYTES`]. The error's text says which check failed
/// ("is a directory", "is not a regular file", "is … larger than …"); callers add the path.
pub fn read_input(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::{Error as IoError, ErrorKind};
    let meta = std::fs::metadata(path)?;
    if meta.is_dir() {
        return Err(IoError::new(ErrorKind::InvalidInput, "is a directory, not a file"));
    }
    if !meta.is_file() {
        return Err(IoError::new(
            ErrorKind::InvalidInput,
            "is not a regular file (a device, FIFO or socket); only regular files are read",
        ));
    }
    let too_big = |n: u64| {
        IoError::new(
            ErrorKind::InvalidInput,
            format!(
                "is {}, larger than the {} an input file may have",
                crate::error::fmt_bytes(n),
                crate::error::fmt_bytes(MAX_INPUT_BYTES)
            ),
        )
    };
    if meta.len() > MAX_INPUT_BYTES {
        return Err(too_big(meta.len()));
    }
    let f = std::fs::File::open(path)?;
    let mut buf = Vec::with_capacity(meta.len() as usize);
    // take(): a file that grows while it is read still stops at the cap.
    f.take(MAX_INPUT_BYTES + 1).read_to_end(&mut buf)?;
    if buf.len() as u64 > MAX_INPUT_BYTES {
        return Err(too_big(buf.len() as u64));
    }
    Ok(buf)
}

/// [`read_input`] as an [`Error`] naming the file (an input error: the reason is said once,
/// not again as a source).
pub(crate) fn read_input_file(path: &Path) -> Result<Vec<u8>> {
    read_input(path).map_err(|e| Error::input(Location::file(path), e.to_string()))
}

/// [`read_input_file`] as text (lossy UTF-8: OBJ files in the wild have Latin-1 comments).
pub(crate) fn read_input_text(path: &Path) -> Result<String> {
    let bytes = read_input_file(path)?;
    Ok(match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    })
}

/// Lines ended by `\n`, `\r\n` or a lone `\r` (old Mac files), without their ends, so that
/// line numbers in errors are right whichever convention a file uses.
pub(crate) fn split_lines(text: &str) -> impl Iterator<Item = &str> + '_ {
    let mut rest = Some(text);
    std::iter::from_fn(move || {
        let s = rest?;
        if s.is_empty() {
            rest = None;
            return None;
        }
        match s.find(['\n', '\r']) {
            Some(i) => {
                let skip = if s[i..].starts_with("\r\n") { 2 } else { 1 };
                rest = Some(&s[i + skip..]);
                Some(&s[..i])
            }
            None => {
                rest = None;
                Some(s)
            }
        }
    })
}

/// A material as written in the input.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialDesc {
    /// Name (MTL `newmtl`, glTF material name).
    pub name: String,
    /// Diffuse reflectance ρ per channel, linear; must be ≥ 0 (≥ 1 is lowered to
    /// [`MAX_REFLECTANCE`] unless [`SceneDesc::strict`]).
    pub reflectance: Rgb,
    /// Emitted radiance L_e per channel (MTL `Ke`); exitance is π·L_e.
    pub emission: Rgb,
    /// Both sides of surfaces with this material reflect (and emit): `Some(true)`; only the
    /// front: `Some(false)`, which holds even when the whole scene is made two-sided (an
    /// emitter that must stay one-sided under `--two-sided`); None: as the scene says
    /// ([`SceneDesc::two_sided`]).
    pub two_sided: Option<bool>,
    /// Where it was defined.
    pub loc: Option<Location>,
    /// A texture that multiplies `reflectance` (glTF `baseColorTexture`, MTL `map_Kd`).
    pub base_texture: Option<TextureRef>,
    /// A texture that multiplies `emission` (glTF `emissiveTexture`, MTL `map_Ke`).
    pub emission_texture: Option<TextureRef>,
    /// Thermal properties (TOML `emissivity`, `temperature`, `heat_flux`, `adiabatic`).
    pub thermal: Option<ThermalDesc>,
}

/// Thermal properties of a material as written ([`crate::thermal`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ThermalDesc {
    /// Hemispherical emissivity ε in [0, 1] (None: 1 − the mean reflectance).
    pub emissivity: Option<f64>,
    /// Emissivity in each wavelength band (TOML `emissivity = [ε₁, ε₂, …]`) of a solve
    /// whose spectrum is split at [`SceneDesc::band_edges`]; empty: grey (`emissivity` in
    /// every band).
    pub band_emissivity: Vec<f64>,
    /// The boundary condition (None: the material takes no part in a thermal solve).
    pub boundary: Option<Boundary>,
}

/// A thermal boundary condition of a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Boundary {
    /// Given temperature, kelvin.
    Temperature(f64),
    /// Given net radiative heat flux leaving the surface, W per unit area (uniform).
    HeatFlux(f64),
    /// No net heat: a re-radiating surface.
    Adiabatic,
}

/// A validated thermal specification: emissivity and boundary condition.
#[derive(Clone, Debug, PartialEq)]
pub struct ThermalSpec {
    /// Emissivity ε in [0, 1] (grey; for a material with per-band values, what the grey
    /// default would be: used by nothing, see [`ThermalSpec::band_emissivity`]).
    pub emissivity: f64,
    /// Emissivity per wavelength band, each in [0, 1]; empty: grey. Computations that
    /// have no bands (Gebhart factors, View3D's emittance-weighted factors, a thermal solve
    /// without band edges) refuse a material that has them.
    pub band_emissivity: Vec<f64>,
    /// The boundary condition.
    pub boundary: Boundary,
}

impl MaterialDesc {
    /// A non-emitting material.
    pub fn diffuse(name: &str, reflectance: Rgb) -> Self {
        MaterialDesc { name: name.into(), reflectance, emission: Rgb::ZERO, two_sided: None, loc: None, base_texture: None, emission_texture: None, thermal: None }
    }
}

/// A named group of polygons (OBJ `o`/`g`, glTF node/mesh); the unit of the report.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectDesc {
    /// Name as written (repeated names are made unique by [`Scene::from_desc`]).
    pub name: String,
    /// Where it starts.
    pub loc: Option<Location>,
}

/// One planar polygon as written: vertices in order, front side by the right-hand rule.
#[derive(Clone, Debug, PartialEq)]
pub struct PolygonDesc {
    /// Vertex positions in scene units.
    pub vertices: Vec<DVec3>,
    /// Index into [`SceneDesc::materials`].
    pub material: u32,
    /// Index into [`SceneDesc::objects`].
    pub object: u32,
    /// Where it was defined (OBJ `f` line).
    pub loc: Option<Location>,
    /// Texture coordinates per set (glTF `TEXCOORD_n`, OBJ `vt` as set 0), one per vertex
    /// (u right, v down the image); empty without.
    pub uvs: Vec<Vec<DVec2>>,
}

/// A sky: what every ray that leaves the geometry sees. Uniform, every direction the same
/// radiance (a constant environment, Mitsuba's `constant` emitter: under it a surface
/// point's irradiance is `π·L_sky·S(x)`, with `S(x)` the cosine-weighted fraction of its
/// hemisphere that sees no polygon, its sky exposure), or an equirectangular
/// [`Environment`] image; and a sun. See [`crate::sky`].
#[derive(Clone, Debug, PartialEq)]
pub struct Sky {
    /// Radiance of the sky, linear RGB (same units as `Ke`); with an environment, zero.
    pub radiance: Rgb,
    /// A sun: a distant disk of light, seen by rays that leave the scene towards it.
    pub sun: Option<Sun>,
    /// An environment image: the radiance by direction (instead of `radiance`).
    pub environment: Option<Environment>,
    /// Portals: openings through which the sky is sampled directly by the final gather
    /// (see [`Portal`]).
    pub portals: Vec<Portal>,
}

/// A sky portal (as pbrt-v4's and Mitsuba's): a convex planar polygon, usually an opening
/// of a building (a courtyard, a window), through which the final gather samples the sky
/// in solid angle instead of finding it with cosine-distributed rays. Sky light that comes
/// in elsewhere is still found by those rays (a ray that leaves the scene through a portal
/// is the portal's share, any other the rays'), so a portal that misses part of an opening
/// changes the noise, not the answer.
#[derive(Clone, Debug, PartialEq)]
pub struct Portal {
    vertices: Vec<DVec3>,
    normal: DVec3,
}

impl Portal {
    /// A portal of `vertices`: at least three finite points spanning a non-zero area, in one
    /// plane (within 1e-6 of their size) and convex; else what is wrong.
    pub fn new(vertices: Vec<DVec3>) -> std::result::Result<Portal, String> {
        if vertices.len() < 3 {
            return Err(format!("a portal needs at least 3 corners, got {}", vertices.len()));
        }
        if let Some(v) = vertices.iter().find(|v| !v.is_finite()) {
            return Err(format!("corner {:?} is not finite", v.to_array()));
        }
        let n = newell_normal(&vertices);
        let size = vertices.iter().map(|v| (*v - vertices[0]).length()).fold(0.0, f64::max);
        if !(n.length() > 1e-12 * size * size) || size <= 0.0 {
            return Err("its corners span no area".into());
        }
        let n = n.normalize();
        if let Some(v) = vertices.iter().find(|v| n.dot(**v - vertices[0]).abs() > 1e-6 * size) {
            return Err(format!("corner {:?} is off the plane of the others", v.to_array()));
        }
        // Convex and simple: every corner on the inner side of every edge (turning the same
        // way at every corner alone lets a star through).
        let m = vertices.len();
        for k in 0..m {
            let (a, b) = (vertices[k], vertices[(k + 1) % m]);
            if vertices.iter().any(|c| n.dot((b - a).cross(*c - a)) < -1e-9 * size * size) {
                return Err("it is not convex (give its corners in order around it, or split it)".into());
            }
        }
        Ok(Portal { vertices, normal: n })
    }

    /// Corners, in order (at least three, convex, planar).
    pub fn vertices(&self) -> &[DVec3] {
        &self.vertices
    }

    /// Unit normal (by the corners' order).
    pub fn normal(&self) -> DVec3 {
        self.normal
    }
}

/// An equirectangular (latitude–longitude) environment: linear radiance by direction, +Y
/// up, as three.js's `EquirectangularReflectionMapping` reads it: the image's top row is
/// the zenith, its middle column looks along +X, and u grows from −X through −Z… as
///
/// ```text
/// u = atan2(d.z, d.x) / 2π + 1/2,   v = 1/2 − asin(d.y) / π   (v down the image)
/// ```
///
/// for the direction `d` turned by `−rotation_deg` about +Y, times `strength`: what the
/// image shows in direction `m` is seen in direction `R_y(rotation)·m` (a positive rotation
/// turns the environment counter-clockwise seen from above; 90° brings +X to −Z).
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    /// The image (linear texels, with its mip pyramid).
    pub texture: Arc<Texture>,
    /// Multiplies every texel.
    pub strength: f64,
    /// Turn about +Y, degrees.
    pub rotation_deg: f64,
}

impl Environment {
    /// Radiance seen in direction `dir` (any length), filtered over about `solid_angle`
    /// steradians (0: the finest level).
    pub fn radiance(&self, dir: DVec3, solid_angle: f64) -> Rgb {
        let d = dir.normalize_or_zero();
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let d = DVec3::new(c * d.x - s * d.z, d.y, s * d.x + c * d.z);
        let u = d.z.atan2(d.x) / std::f64::consts::TAU + 0.5;
        let v = 0.5 - d.y.clamp(-1.0, 1.0).asin() / std::f64::consts::PI;
        let (w, h) = self.texture.size();
        // A texel at the equator spans (2π/w)·(π/h) steradians.
        let texel = std::f64::consts::TAU * std::f64::consts::PI / (w * h) as f64;
        let lod = if solid_angle > texel { 0.5 * (solid_angle / texel).log2() } else { 0.0 };
        let tref = TextureRef { wrap: [texture::Wrap::Repeat, texture::Wrap::ClampToEdge], ..TextureRef::new(0, 0) };
        self.texture.sample(&tref, DVec2::new(u, v), lod) * self.strength
    }

    /// The largest radiance of any texel.
    pub fn max(&self) -> Rgb {
        self.texture.max * self.strength
    }
}

/// The sun of a [`Sky`]: a disk of uniform radiance at infinity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sun {
    /// Unit vector from the scene towards the sun's centre.
    pub direction: DVec3,
    /// Irradiance on a surface facing the sun, unshadowed (W/m² per channel in the units
    /// of exitance, E = π·Ke): a surface with normal `n` gets `E · max(0, n·direction)`.
    pub irradiance: Rgb,
    /// Angular diameter of the disk, degrees (the real sun: 0.53; 0 is a point).
    pub angular_diameter_deg: f64,
}

impl Sun {
    /// Cosine of the disk's angular radius.
    pub fn cos_radius(&self) -> f64 {
        (0.5 * self.angular_diameter_deg).to_radians().cos()
    }

    /// Radiance of the disk (irradiance over its solid angle), for a camera ray that meets
    /// it; infinite for a point sun (never met).
    pub fn radiance(&self) -> Rgb {
        let omega = 2.0 * std::f64::consts::PI * (1.0 - self.cos_radius());
        self.irradiance / omega
    }

    /// True if the sun gives light.
    pub fn is_lit(&self) -> bool {
        self.irradiance.max_element() > 0.0
    }
}

impl Sky {
    /// A uniform sky of radiance `radiance`, with no sun.
    pub fn uniform(radiance: Rgb) -> Sky {
        Sky { radiance, sun: None, environment: None, portals: Vec::new() }
    }

    /// True if the sky or its sun gives light.
    pub fn is_lit(&self) -> bool {
        self.radiance.max_element() > 0.0
            || self.sun.is_some_and(|s| s.is_lit())
            || self.environment.as_ref().is_some_and(|e| e.max().max_element() > 0.0)
    }

    /// True if the sky itself (not its sun) gives light.
    pub fn has_radiance(&self) -> bool {
        self.radiance.max_element() > 0.0 || self.environment.as_ref().is_some_and(|e| e.max().max_element() > 0.0)
    }

    /// Radiance of the sky seen in direction `dir` (the sun's disk not included), filtered
    /// over about `solid_angle` steradians.
    #[inline]
    pub fn radiance_in(&self, dir: DVec3, solid_angle: f64) -> Rgb {
        match &self.environment {
            Some(env) => env.radiance(dir, solid_angle),
            None => self.radiance,
        }
    }

    /// The sun, if it gives light.
    pub fn lit_sun(&self) -> Option<Sun> {
        self.sun.filter(Sun::is_lit)
    }
}

/// A light that is not a surface (KHR_lights_punctual, TOML `[[lights]]`): a point, a spot
/// or a directional light. Its direct light at a surface point is exact up to a shadow ray
/// ([`crate::lights`]); its reflections go through the radiosity system like the sky's.
///
/// Units: the scene's radiometric units, like `Ke`. A point or spot light's `intensity` is
/// radiant intensity I (per steradian; glTF's candela taken as is, without 683 lm/W), so a
/// surface at distance r facing it receives I/r², and a small emitter of radiance `Ke` and
/// area A, seen face on, has the same intensity as a point light of I = Ke·A. A directional
/// light's `intensity` is the irradiance on a surface facing it (glTF's lux taken as is).
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// A name for messages ("light 2", the glTF light's name).
    pub name: String,
    /// What kind, and where.
    pub kind: LightKind,
    /// Radiant intensity (point, spot) or irradiance (directional), linear RGB.
    pub intensity: Rgb,
    /// Where it was defined.
    pub loc: Option<Location>,
}

/// The kinds of [`Light`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// Light from a point, the same in every direction.
    Point {
        /// Position.
        position: DVec3,
    },
    /// A point light limited to a cone: full inside `inner_cone` (radians from the axis),
    /// none beyond `outer_cone`, between them glTF's smooth falloff
    /// `clamp((cos θ − cos outer)/(cos inner − cos outer), 0, 1)²`.
    Spot {
        /// Position.
        position: DVec3,
        /// Unit vector of the cone's axis: where the light goes.
        direction: DVec3,
        /// Half-angle of full intensity, radians (glTF `innerConeAngle`, default 0).
        inner_cone: f64,
        /// Half-angle where it reaches zero, radians (glTF `outerConeAngle`, default π/4).
        outer_cone: f64,
    },
    /// Parallel light from infinitely far, like a sun of no size.
    Directional {
        /// Unit vector of where the light goes (glTF: the node's −Z).
        direction: DVec3,
    },
}

impl Light {
    /// True if it gives light.
    pub fn is_lit(&self) -> bool {
        self.intensity.max_element() > 0.0
    }
}

/// A scene as read from a file, before validation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneDesc {
    /// A short name (file stem or built-in name).
    pub name: String,
    /// Materials.
    pub materials: Vec<MaterialDesc>,
    /// Objects.
    pub objects: Vec<ObjectDesc>,
    /// Polygons.
    pub polygons: Vec<PolygonDesc>,
    /// The scene's own camera, if it has one.
    pub camera: Option<Camera>,
    /// Treat every surface as two-sided.
    pub two_sided: bool,
    /// Objects that only block rays (View3D `O` surfaces): they shadow, but view-factor
    /// matrices give them no row or column. Indices into [`SceneDesc::objects`].
    pub obstructions: Vec<u32>,
    /// Warnings met while reading.
    pub warnings: Vec<Warning>,
    /// Refuse a reflectance channel ≥ 1 instead of lowering it to [`MAX_REFLECTANCE`].
    pub strict: bool,
    /// Light sources in the file that are not surfaces and were ignored, in words (e.g.
    /// "light 'x' of type \"area\" is ignored"), for the error of a
    /// scene without light ([`Scene::check_emits`]).
    pub ignored_lights: Vec<String>,
    /// A uniform sky around the geometry (TOML `[sky]`, the CLI's `--sky`).
    pub sky: Option<Sky>,
    /// Point, spot and directional lights (glTF KHR_lights_punctual, TOML `[[lights]]`).
    pub lights: Vec<Light>,
    /// Decoded textures, indexed by [`TextureRef::texture`].
    pub textures: Vec<Arc<Texture>>,
    /// Wavelengths in µm, increasing, that split the spectrum into bands for a thermal
    /// solve with per-band emissivities (TOML `[thermal] band_edges`; empty: grey).
    pub band_edges: Vec<f64>,
    /// The node hierarchy of a glTF input (None for other inputs, or several meshes).
    pub node_tree: Option<Arc<NodeTree>>,
}

/// The node hierarchy of a glTF scene as read (the nodes reached from its scene), kept so
/// that `radiosity bake` can write the baked scene back with the same nodes, names and
/// transforms ([`crate::output::gltf`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeTree {
    /// The nodes, parents before their children.
    pub nodes: Vec<SceneNode>,
    /// Per object (index into the scene's objects, all from this file): its node.
    pub object_nodes: Vec<u32>,
}

/// One node of a [`NodeTree`].
#[derive(Clone, Debug, PartialEq)]
pub struct SceneNode {
    /// Its name in the file.
    pub name: Option<String>,
    /// Its own transform (relative to its parent).
    pub local: glam::DMat4,
    /// Its transform to the scene (the product down from its root).
    pub world: glam::DMat4,
    /// Its parent (index into [`NodeTree::nodes`]); None for a root.
    pub parent: Option<u32>,
}

/// A validated material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name.
    pub name: String,
    /// Diffuse reflectance ρ in [0,1) per channel; with a texture, the texture's mean
    /// times the factor (per point and per element: [`Scene::reflectance_at`],
    /// [`Scene::surface_means`]).
    pub reflectance: Rgb,
    /// Emitted radiance L_e per channel (W/(m²·sr) or scene units); with a texture, its
    /// mean times the factor.
    pub emission: Rgb,
    /// Whether surfaces with it are two-sided (already expanded into polygons).
    pub two_sided: bool,
    /// The reflectance texture and the factor it is multiplied by.
    pub base_texture: Option<(TextureRef, Rgb)>,
    /// The emission texture and its factor.
    pub emission_texture: Option<(TextureRef, Rgb)>,
    /// Emissivity and boundary condition for [`crate::thermal`] (None: none given).
    pub thermal: Option<ThermalSpec>,
}

impl Material {
    /// Emitted exitance E = π·L_e.
    pub fn exitance(&self) -> Rgb {
        self.emission * std::f64::consts::PI
    }
    /// True if it emits light.
    pub fn is_emitter(&self) -> bool {
        self.emission.max_element() > 0.0
    }
    /// True if a texture varies its reflectance or emission.
    pub fn is_textured(&self) -> bool {
        self.base_texture.is_some() || self.emission_texture.is_some()
    }
}

/// A validated object: a name unique within the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// Unique name (a repeated input name gets `#k`, k-th occurrence in file order).
    pub name: String,
}

/// A validated polygon: planar, convex, at least 3 vertices, non-zero area.
#[derive(Clone, Debug, PartialEq)]
pub struct Polygon {
    /// Vertices, counter-clockwise about `normal`.
    pub vertices: Vec<DVec3>,
    /// Unit normal of the front side.
    pub normal: DVec3,
    /// Area in scene units².
    pub area: f64,
    /// Material index.
    pub material: u32,
    /// Object index.
    pub object: u32,
    /// True for the generated back side of a two-sided input polygon.
    pub back_side: bool,
    /// True when the polygon is one side of a two-sided pair (a coincident polygon with the
    /// opposite normal exists): renderers and probes then ignore its back face.
    pub two_sided: bool,
    /// Where the input polygon it came from was defined (OBJ `f` line), for messages.
    pub loc: Option<Location>,
    /// Texture coordinates per set as affine maps of the plane (empty without).
    pub uv: Vec<UvMap>,
}

impl Polygon {
    /// Area-weighted centroid.
    pub fn centroid(&self) -> DVec3 {
        polygon_centroid(&self.vertices)
    }
}

/// A validated scene, ready for meshing.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// Short name.
    pub name: String,
    /// Materials.
    pub materials: Vec<Material>,
    /// Objects (report units).
    pub objects: Vec<Object>,
    /// Planar convex polygons.
    pub polygons: Vec<Polygon>,
    /// The scene's camera, if any.
    pub camera: Option<Camera>,
    /// Warnings from reading and validation (skipped geometry, defaults used).
    pub warnings: Vec<Warning>,
    /// Obstruction-only objects, sorted (see [`SceneDesc::obstructions`]).
    pub obstructions: Vec<u32>,
    /// The scene's file (the first polygon's), or its name for built-in scenes.
    pub file: PathBuf,
    /// Light lost on the way, in words: emitting polygons skipped by validation and
    /// [`SceneDesc::ignored_lights`] (see [`Scene::check_emits`]).
    pub lost_light: Vec<String>,
    /// The sky, if any (validated: finite, non-negative, not all zero).
    pub sky: Option<Sky>,
    /// Point, spot and directional lights that give light (validated; dark ones dropped).
    pub lights: Vec<Light>,
    /// Decoded textures ([`Material::base_texture`], [`Material::emission_texture`]).
    pub textures: Vec<Arc<Texture>>,
    /// Thermal band edges in µm (validated: finite, positive, increasing).
    pub band_edges: Vec<f64>,
    /// The node hierarchy of a glTF input (see [`SceneDesc::node_tree`]).
    pub node_tree: Option<Arc<NodeTree>>,
}

impl Scene {
    /// Validates a description (see the module docs for the rules).
    pub fn from_desc(desc: SceneDesc) -> Result<Scene> {
        validate::validate(desc)
    }

    /// Axis-aligned bounds (min, max) of all polygons.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in &self.polygons {
            for v in &p.vertices {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        (lo, hi)
    }

    /// Length of the bounding-box diagonal (the scene's size).
    pub fn diagonal(&self) -> f64 {
        let (lo, hi) = self.bounds();
        if lo.x > hi.x {
            0.0
        } else {
            (hi - lo).length()
        }
    }

    /// Total surface area.
    pub fn total_area(&self) -> f64 {
        self.polygons.iter().map(|p| p.area).sum()
    }

    /// True if some polygon emits light.
    pub fn has_emitter(&self) -> bool {
        self.polygons.iter().any(|p| self.materials[p.material as usize].is_emitter())
    }

    /// The sky, if it gives light.
    pub fn lit_sky(&self) -> Option<&Sky> {
        self.sky.as_ref().filter(|s| s.is_lit())
    }

    /// True if some polygon emits light, the sky gives light or there is a light.
    pub fn has_light(&self) -> bool {
        self.has_emitter() || self.lit_sky().is_some() || !self.lights.is_empty()
    }

    /// True if light comes from outside the surfaces: a lit sky or a [`Light`]. Its
    /// direct irradiance is computed per element by [`crate::lights::element_irradiance`].
    pub fn has_external_light(&self) -> bool {
        self.lit_sky().is_some() || !self.lights.is_empty()
    }

    /// An error when no surface emits light and there is no sky (a render or solve would be all black), saying
    /// what was skipped or ignored: emitting polygons dropped as degenerate, lights of a kind
    /// not supported. View factors need no light and do not call this.
    pub fn check_emits(&self) -> Result<()> {
        if self.has_light() {
            return Ok(());
        }
        let why = if self.lost_light.is_empty() {
            "no material has a positive emission (OBJ/MTL Ke, glTF emissiveFactor, TOML emission) and \
             there is no sky (TOML [sky], --sky) and no light (TOML [[lights]], glTF KHR_lights_punctual), \
             so the image would be black"
                .to_string()
        } else {
            self.lost_light.join("; ")
        };
        // Assets that name their light instead of giving it an emission (a glTF Cornell box
        // whose material is called "light", an OBJ without Ke): say how to light it.
        let mut used = vec![false; self.materials.len()];
        for p in &self.polygons {
            used[p.material as usize] = true;
        }
        let named: Vec<&str> = self
            .materials
            .iter()
            .zip(&used)
            .filter(|(m, u)| **u && !m.is_emitter())
            .map(|(m, _)| m.name.as_str())
            .filter(|n| ["light", "lamp", "emit", "emissive"].iter().any(|k| n.to_lowercase().contains(k)))
            .take(3)
            .collect();
        let hint = match named.first() {
            Some(first) => {
                // A TOML bare key, or a quoted one.
                let bare = first.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
                let first = if bare { first.to_string() } else { format!("{first:?}") };
                let file = self.file.file_name().map_or("scene.obj".into(), |f| f.to_string_lossy().into_owned());
                format!(
                    "; {} look{} like a light: give {} an emission in a TOML scene, e.g. mesh = \"{file}\" with [materials.{first}] emission = [10, 10, 10] (radiance)",
                    named.iter().map(|n| format!("material '{n}'")).collect::<Vec<_>>().join(", "),
                    if named.len() == 1 { "s" } else { "" },
                    if named.len() == 1 { "it" } else { "them" },
                )
            }
            None => String::new(),
        };
        Err(Error::input(Location::file(&self.file), format!("no surface emits light: {why}{hint}")))
    }

    /// A textured channel of polygon `poly` at point `x`, filtered over `footprint` (scene
    /// units², 0 for the finest texels); None when the material has no such texture or the
    /// polygon no coordinates for it.
    fn textured_at(&self, poly: usize, tex: &Option<(TextureRef, Rgb)>, x: DVec3, footprint: f64) -> Option<Rgb> {
        let (tref, factor) = tex.as_ref()?;
        let map = self.polygons[poly].uv.get(tref.tex_coord as usize)?;
        let t = self.textures.get(tref.texture as usize)?;
        Some(t.at_point(tref, map, x, footprint) * *factor)
    }

    /// Reflectance of polygon `poly` at point `x` (the texel under it times the factor,
    /// lowered to [`MAX_REFLECTANCE`]), filtered over `footprint` scene units².
    pub fn reflectance_at(&self, poly: usize, x: DVec3, footprint: f64) -> Rgb {
        let m = &self.materials[self.polygons[poly].material as usize];
        match self.textured_at(poly, &m.base_texture, x, footprint) {
            Some(r) => r.min(Rgb::splat(MAX_REFLECTANCE)),
            None => m.reflectance,
        }
    }

    /// Emitted radiance of polygon `poly` at point `x`.
    pub fn emission_at(&self, poly: usize, x: DVec3, footprint: f64) -> Rgb {
        let m = &self.materials[self.polygons[poly].material as usize];
        self.textured_at(poly, &m.emission_texture, x, footprint).unwrap_or(m.emission)
    }

    /// Mean reflectance and emitted radiance over a convex piece (`corners`) of polygon
    /// `poly`: the textures integrated over it times the factors (the material's constants
    /// where it has no texture).
    pub fn surface_means(&self, poly: usize, corners: &[DVec3]) -> (Rgb, Rgb) {
        let p = &self.polygons[poly];
        let m = &self.materials[p.material as usize];
        let mean = |tex: &Option<(TextureRef, Rgb)>| -> Option<Rgb> {
            let (tref, factor) = tex.as_ref()?;
            let map = p.uv.get(tref.tex_coord as usize)?;
            let t = self.textures.get(tref.texture as usize)?;
            Some(t.mean_over(tref, map, corners) * *factor)
        };
        let rho = mean(&m.base_texture).map_or(m.reflectance, |r| r.min(Rgb::splat(MAX_REFLECTANCE)));
        (rho, mean(&m.emission_texture).unwrap_or(m.emission))
    }

    /// True if `object` only blocks rays (see [`SceneDesc::obstructions`]).
    pub fn is_obstruction(&self, object: u32) -> bool {
        self.obstructions.binary_search(&object).is_ok()
    }
}

/// Reads a scene: a built-in name (`cornell`, `furnace`) or a file (`.obj`, `.gltf`, `.glb`,
/// `.toml`, `.vs3`), chosen by extension.
pub fn load(spec: &str) -> Result<SceneDesc> {
    if let Some(desc) = builtin::by_name(spec) {
        return Ok(desc);
    }
    let path = Path::new(spec);
    if path.is_dir() {
        return Err(Error::input(Location::file(path), "is a directory, not a scene file"));
    }
    if !path.exists() {
        let names = builtin::NAMES.join(", ");
        return Err(Error::Invalid(format!(
            "{spec}: no such file (and not a built-in scene; built-in scenes are: {names})"
        )));
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).unwrap_or_default();
    match ext.as_str() {
        "obj" => obj::load_obj(path),
        "gltf" | "glb" => gltf::load_gltf(path),
        "toml" => toml_file::load_toml(path),
        "vs3" => vs3::load_vs3(path),
        other => Err(Error::input(
            Location::file(path),
            format!("unknown scene format '.{other}' (expected .obj, .gltf, .glb, .toml or .vs3)"),
        )),
    }
}

/// Reads and validates a scene in one step.
pub fn load_scene(spec: &str) -> Result<Scene> {
    Scene::from_desc(load(spec)?)
}

/// Area-weighted centroid of a planar polygon (fan decomposition).
pub fn polygon_centroid(v: &[DVec3]) -> DVec3 {
    let c0 = v[0];
    let mut acc = DVec3::ZERO;
    let mut wsum = 0.0;
    for i in 1..v.len() - 1 {
        let w = (v[i] - c0).cross(v[i + 1] - c0).length();
        acc += w * (c0 + v[i] + v[i + 1]) / 3.0;
        wsum += w;
    }
    if wsum > 0.0 {
        acc / wsum
    } else {
        v.iter().copied().sum::<DVec3>() / v.len() as f64
    }
}
