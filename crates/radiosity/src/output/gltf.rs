//! Baked light as glTF 2.0 binary (`.glb`): the solved mesh with per-vertex `COLOR_0`.
//!
//! glTF defines `COLOR_0` as a linear multiplier of the base colour, and a material with
//! `KHR_materials_unlit` is shown as base colour × `COLOR_0`, with no lighting of the
//! viewer's own (three.js `MeshBasicMaterial`, Blender, Babylon, `<model-viewer>`). Vertex
//! colours must lie in [0, 1] (the Khronos validator's `ACCESSOR_NON_CLAMPED` error), so
//! they hold what a display shows: the radiance times the exposure, clipped,
//!
//! ```text
//! base colour = 1,   COLOR_0 = clamp(k · B_v / π, 0, 1)
//! ```
//!
//! with `B_v` the reconstructed radiosity of vertex `v` ([`crate::reconstruct`], the values
//! Gouraud rendering interpolates) and `k` the exposure — the same values, before the sRGB
//! encoding, as a PNG of `render` at that exposure. Keeping the base colour at the
//! reflectance and `COLOR_0` at the irradiance (so that a texture could multiply it) would
//! need colours above 1 wherever a surface is lit brighter than white; that split is the
//! lightmaps' job. Each material keeps its reflectance and emitted radiance in its
//! `extras` (`radiosity.reflectance`, `radiosity.emission`). A viewer that ignores
//! `KHR_materials_unlit` lights the surfaces again with its own lights (the extension is
//! used, not required). Emitters also get `emissiveFactor` = their radiance × `k`, clipped.
//!
//! With a lightmap ([`baked_glb`]; texels from [`crate::render::lightmap`] on the atlas of
//! [`crate::mesh::atlas`]) every primitive also gets `TEXCOORD_1` (the atlas) and
//! `TEXCOORD_0` (its chart's planar coordinates in scene units), and every material shows
//! the lightmap — radiance × exposure, 8-bit sRGB PNG in the buffer — as its
//! `emissiveTexture` on texture coordinate 1, with a black base colour and no
//! `KHR_materials_unlit`: core glTF that every viewer draws as is (emission is not lit).
//! The vertex colours stay.
//!
//! The other lightmap mode, [`LightmapMode::Moz`], follows Mozilla Hubs' `MOZ_lightmap`
//! (three.js's `lightMap`; the convention Hubs, Spoke and three.js's exporter write): the
//! lightmap holds the *irradiance* `E` arriving at each texel, and the viewer multiplies it
//! by the material's own base colour, so texture detail stays at the texture's resolution:
//!
//! ```text
//! shown = baseColour(uv₀) · texel(uv₁) · intensity / π,   texel · intensity = k · E
//! ```
//!
//! Materials keep their reflectance as `baseColorFactor` and their `baseColorTexture`
//! (re-encoded as sRGB PNG, its coordinate set and transform applied to `TEXCOORD_0`, its
//! wrap modes in the sampler), emitters their radiance × `k` (clipped) as
//! `emissiveFactor`; there are no vertex colours and no `KHR_materials_unlit`. The lightmap
//! is an 8-bit *linear* PNG (three.js and Hubs read it as data, with no transfer function)
//! scaled into [0, 1] by `intensity` (the 99.9th percentile of `k·E`; brighter texels are
//! clipped). `MOZ_lightmap` is used, not required: a viewer that does not know it shows
//! the plain materials lit by its own lights. three.js's standard material takes a few
//! per cent of the diffuse light for its specular layer; `MeshLambertMaterial` shows the
//! formula above exactly (the check page and the viewer switch to it).
//!
//! Geometry: one node per scene object (its name) — for a glTF input, the input's own node
//! tree (names, local transforms, children) with each object's mesh on its node, in that
//! node's frame — one mesh with one triangle primitive per material; quadrilateral elements are split into two triangles; vertices are the
//! mesh's, which are shared inside a patch and separate across patches, so light stays
//! continuous on a wall and sharp at its corners. Both sides of a two-sided surface are
//! written (opposite windings, `doubleSided` false), each with its own light. Positions are
//! in the scene's units, as read. The scene's camera becomes a glTF perspective camera.
//! The asset's `extras` hold the exposure and the convention, so tools can undo it.

use std::collections::BTreeMap;

use glam::{DMat3, DQuat, DVec3};
use gltf::json;
use json::validation::{Checked::Valid, USize64};

use crate::mesh::Mesh;
use crate::scene::{Camera, Scene};
use crate::{Error, Result, Rgb};

/// What to write.
#[derive(Clone, Debug)]
pub struct Options {
    /// Radiance is multiplied by this before it is written (see the module docs).
    pub exposure: f64,
    /// The camera to include as a glTF camera node (None: none).
    pub camera: Option<Camera>,
    /// `asset.generator`.
    pub generator: String,
}

/// The automatic exposure of a bake: 0.8 over the 97th percentile (by area) of the
/// elements' radiance in their brightest channel, emitters left out unless every surface
/// emits. [`super::auto_exposure`] takes the luminance of image pixels; a vertex colour is
/// clipped channel by channel, and by luminance a saturated surface (a red box, 0.21 of
/// its red in luminance) had its red channel clipped at every vertex (flat, unshaded).
/// For grey surfaces the two agree.
pub fn auto_exposure(scene: &Scene, mesh: &Mesh, element_b: &[Rgb]) -> f64 {
    let radiance = |with_emitters: bool| -> Vec<(f64, f64)> {
        mesh.elements
            .iter()
            .zip(element_b)
            .filter(|(e, _)| with_emitters || !scene.materials[scene.polygons[e.patch as usize].material as usize].is_emitter())
            .map(|(e, b)| (b.max_element() / std::f64::consts::PI, e.area))
            .filter(|(l, _)| *l > 0.0 && l.is_finite())
            .collect()
    };
    // Every surface emits (a furnace): then the emitters are what there is to see.
    let mut v = radiance(false);
    if v.is_empty() {
        v = radiance(true);
    }
    weighted_percentile(v, 0.97).map_or(1.0, |l| 0.8 / l)
}

/// The value below which the fraction `q` of the total weight lies, of (value, weight)
/// pairs (None for none).
fn weighted_percentile(mut v: Vec<(f64, f64)>, q: f64) -> Option<f64> {
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|x| x.1).sum();
    let mut acc = 0.0;
    for (x, w) in &v {
        acc += w;
        if acc >= q * total {
            return Some(*x);
        }
    }
    v.last().map(|x| x.0)
}

/// How a lightmap is wired into the materials (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightmapMode {
    /// Radiance × exposure as every material's `emissiveTexture` over a black base colour:
    /// core glTF, shown the same by every viewer; texture detail only at the lightmap's
    /// resolution.
    #[default]
    Emissive,
    /// Irradiance in `MOZ_lightmap`, multiplied by the material's own base colour and
    /// texture (kept); viewers without the extension light the materials themselves.
    Moz,
}

impl LightmapMode {
    /// Every mode.
    pub const ALL: [LightmapMode; 2] = [LightmapMode::Emissive, LightmapMode::Moz];

    /// Command-line name.
    pub fn name(self) -> &'static str {
        match self {
            LightmapMode::Emissive => "emissive",
            LightmapMode::Moz => "moz",
        }
    }
}

impl std::str::FromStr for LightmapMode {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        LightmapMode::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| {
            Error::Invalid(format!("unknown lightmap mode '{s}' (use emissive or moz)"))
        })
    }
}

/// A lightmap to wire into the baked scene.
#[derive(Clone, Copy, Debug)]
pub struct Lightmap<'a> {
    /// The atlas (`TEXCOORD_1`).
    pub atlas: &'a crate::mesh::atlas::Atlas,
    /// The lightmap image as PNG: radiance × exposure in sRGB ([`LightmapMode::Emissive`]),
    /// or irradiance × exposure / `intensity`, linear ([`LightmapMode::Moz`]).
    pub png: &'a [u8],
    /// The mode.
    pub mode: LightmapMode,
    /// `MOZ_lightmap.intensity` (the scale the PNG's texels are multiplied by).
    pub intensity: f64,
}

/// The reflectance below which a tenth of the scene's reflecting area lies (the largest
/// channel of each polygon's mean reflectance, area-weighted; 0 when nothing reflects):
/// [`moz_lightmap_png`] clips only irradiance that saturates a display on surfaces at least
/// this bright.
pub fn moz_reference_reflectance(scene: &Scene) -> f64 {
    let v: Vec<(f64, f64)> = scene
        .polygons
        .iter()
        .map(|p| (scene.materials[p.material as usize].reflectance.max_element(), p.area))
        .filter(|(r, a)| *r > 0.0 && *a > 0.0)
        .collect();
    weighted_percentile(v, 0.1).unwrap_or(0.0)
}

/// The `MOZ_lightmap` image of an irradiance lightmap `img` at `exposure`: an 8-bit linear
/// PNG of `k·E / intensity`, with `intensity` the 99.9th percentile of the texels' largest
/// channel of `k·E`, or less: `π / rho_ref`, where a surface of reflectance `rho_ref` (see
/// [`moz_reference_reflectance`]; 0: no such bound) shows white (`ρ·k·E/π ≥ 1`), so the
/// 256 levels go to what a display can show — a lamp's hot spot would otherwise leave the
/// walls a few levels. Texels above are clipped: their count is returned too.
pub fn moz_lightmap_png(img: &crate::render::Image, exposure: f64, rho_ref: f64) -> Result<(Vec<u8>, f64, usize)> {
    let mut peaks: Vec<f64> = img.pixels.iter().map(|p| p.max_element() * exposure).filter(|x| *x > 0.0 && x.is_finite()).collect();
    let mut intensity = if peaks.is_empty() {
        1.0
    } else {
        let k = ((peaks.len() as f64 * 0.999) as usize).min(peaks.len() - 1);
        *peaks.select_nth_unstable_by(k, f64::total_cmp).1
    };
    if rho_ref > 0.0 && rho_ref.is_finite() {
        intensity = intensity.min(std::f64::consts::PI / rho_ref);
    }
    let scale = exposure / intensity;
    let mut clipped = 0;
    let rgb: Vec<u8> = img
        .pixels
        .iter()
        .flat_map(|p| {
            let c = (*p * scale).to_array();
            clipped += c.iter().any(|x| *x > 1.0) as usize;
            c.map(|x| (255.0 * x.clamp(0.0, 1.0)).round() as u8)
        })
        .collect();
    Ok((super::png::encode_rgb8_as(img.width, img.height, &rgb, false)?, intensity, clipped))
}

/// Summary of what was written.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    /// Triangles written.
    pub triangles: usize,
    /// Vertices written.
    pub vertices: usize,
    /// Vertex colour channels clipped to 1.
    pub clipped: usize,
}

struct Buffer {
    bytes: Vec<u8>,
    views: Vec<json::buffer::View>,
    accessors: Vec<json::Accessor>,
}

impl Buffer {
    /// Vertex data of `N` floats per vertex (`type_` VEC2 or VEC3), with its min and max
    /// when asked (POSITION must have them).
    fn push_f32<const N: usize>(&mut self, data: &[[f32; N]], type_: json::accessor::Type, min_max: bool) -> json::Index<json::Accessor> {
        let offset = self.bytes.len();
        for x in data.iter().flatten() {
            self.bytes.extend(x.to_le_bytes());
        }
        let (min, max) = if min_max {
            let mut lo = [f32::INFINITY; N];
            let mut hi = [f32::NEG_INFINITY; N];
            for v in data {
                for k in 0..N {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            (Some(json::serialize::to_value(lo.to_vec()).unwrap()), Some(json::serialize::to_value(hi.to_vec()).unwrap()))
        } else {
            (None, None)
        };
        let target = json::buffer::Target::ArrayBuffer;
        self.view_and_accessor(offset, data.len(), target, json::accessor::ComponentType::F32, type_, min, max)
    }

    fn push_u32(&mut self, data: &[u32]) -> json::Index<json::Accessor> {
        let offset = self.bytes.len();
        for x in data {
            self.bytes.extend(x.to_le_bytes());
        }
        self.view_and_accessor(
            offset,
            data.len(),
            json::buffer::Target::ElementArrayBuffer,
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            None,
            None,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn view_and_accessor(
        &mut self,
        offset: usize,
        count: usize,
        target: json::buffer::Target,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        min: Option<json::Value>,
        max: Option<json::Value>,
    ) -> json::Index<json::Accessor> {
        let view = json::Index::push(
            &mut self.views,
            json::buffer::View {
                buffer: json::Index::new(0),
                byte_length: USize64::from(self.bytes.len() - offset),
                byte_offset: Some(USize64::from(offset)),
                byte_stride: None,
                name: None,
                target: Some(Valid(target)),
                extensions: None,
                extras: Default::default(),
            },
        );
        json::Index::push(
            &mut self.accessors,
            json::Accessor {
                buffer_view: Some(view),
                byte_offset: None,
                count: USize64::from(count),
                component_type: Valid(json::accessor::GenericComponentType(component)),
                extensions: None,
                extras: Default::default(),
                type_: Valid(type_),
                min,
                max,
                name: None,
                normalized: false,
                sparse: None,
            },
        )
    }
}

/// One primitive's vertices and triangles, in the mesh's vertex numbering until written.
#[derive(Default)]
struct Part {
    /// Mesh vertex → local index.
    local: BTreeMap<u32, u32>,
    vertices: Vec<u32>,
    normals: Vec<DVec3>,
    /// The patch of every vertex (vertices are not shared across patches).
    patches: Vec<u32>,
    indices: Vec<u32>,
}

impl Part {
    fn vertex(&mut self, v: u32, n: DVec3, patch: u32) -> u32 {
        let next = self.vertices.len() as u32;
        *self.local.entry(v).or_insert_with(|| {
            self.vertices.push(v);
            self.normals.push(n);
            self.patches.push(patch);
            next
        })
    }
}

/// The glTF camera node's rotation for a camera (glTF cameras look along −Z, up +Y).
fn camera_rotation(c: &Camera) -> DQuat {
    let f = (c.look_at - c.position).normalize();
    let r = f.cross(c.up).normalize();
    let u = r.cross(f);
    DQuat::from_mat3(&DMat3::from_cols(r, u, -f)).normalize()
}

/// The scene with its light baked into per-vertex `COLOR_0`, as GLB bytes. `vertex_b` is
/// the radiosity per mesh vertex ([`crate::reconstruct::vertex_radiosity`] of the display
/// radiosity).
pub fn vertex_colors_glb(scene: &Scene, mesh: &Mesh, vertex_b: &[Rgb], opts: &Options) -> Result<(Vec<u8>, Stats)> {
    baked_glb(scene, mesh, vertex_b, None, opts)
}

/// [`vertex_colors_glb`], and with a `lightmap` also `TEXCOORD_1` from its atlas and the
/// lightmap wired in by its mode: every material's `emissiveTexture` over a black base
/// colour (the core-glTF way that every viewer follows), or `MOZ_lightmap` under the
/// materials' own colours and textures (see the module docs).
pub fn baked_glb(scene: &Scene, mesh: &Mesh, vertex_b: &[Rgb], lightmap: Option<Lightmap<'_>>, opts: &Options) -> Result<(Vec<u8>, Stats)> {
    if vertex_b.len() != mesh.positions.len() {
        return Err(Error::Invalid(format!("{} vertex values for {} vertices", vertex_b.len(), mesh.positions.len())));
    }
    if !(opts.exposure.is_finite() && opts.exposure > 0.0) {
        return Err(Error::Invalid(format!("exposure {} must be a positive number", opts.exposure)));
    }
    // Primitives by (object, material), in element order.
    let mut parts: BTreeMap<(u32, u32), Part> = BTreeMap::new();
    for e in &mesh.elements {
        let p = &scene.polygons[e.patch as usize];
        let part = parts.entry((p.object, p.material)).or_default();
        let n = e.vertex_count();
        let ids: Vec<u32> = (0..n).map(|k| part.vertex(e.vertices[k], e.normal, e.patch)).collect();
        part.indices.extend([ids[0], ids[1], ids[2]]);
        if n == 4 {
            part.indices.extend([ids[0], ids[2], ids[3]]);
        }
    }

    let mut stats = Stats::default();
    let mut root = json::Root {
        asset: json::Asset {
            copyright: None,
            extensions: None,
            extras: Default::default(),
            generator: Some(opts.generator.clone()),
            min_version: None,
            version: "2.0".into(),
        },
        extensions_used: vec!["KHR_materials_unlit".into()],
        ..Default::default()
    };
    let extras = serde_json::json!({ "radiosity": {
        "exposure": opts.exposure,
        "color_0": "radiance x exposure, clipped to 1 (base colour 1, KHR_materials_unlit)",
        "units": "scene units as read"
    }});
    root.asset.extras = Some(serde_json::value::to_raw_value(&extras).map_err(|e| Error::Invalid(e.to_string()))?);

    // The lightmap image, stored first in the buffer.
    let mut buf = Buffer { bytes: Vec::new(), views: Vec::new(), accessors: Vec::new() };
    let clamp = [crate::scene::Wrap::ClampToEdge; 2];
    let lightmap_texture = lightmap.map(|lm| push_png_texture(&mut root, &mut buf, "lightmap", lm.png, clamp, false));
    let moz = lightmap.filter(|lm| lm.mode == LightmapMode::Moz);
    if let Some(lm) = lightmap {
        root.extensions_used.clear();
        if lm.mode == LightmapMode::Moz {
            if !(lm.intensity.is_finite() && lm.intensity > 0.0) {
                return Err(Error::Invalid(format!("lightmap intensity {} must be a positive number", lm.intensity)));
            }
            root.extensions_used.push("MOZ_lightmap".into());
        }
    }
    // MOZ_lightmap: the base-colour and emission textures kept (sRGB PNG, one glTF texture
    // per scene texture and wrap mode).
    let mut base_textures: BTreeMap<(u32, [u8; 2]), json::Index<json::Texture>> = BTreeMap::new();
    if moz.is_some() {
        for m in parts.keys().map(|k| &scene.materials[k.1 as usize]) {
            for tref in [m.base_texture.as_ref().map(|t| &t.0), kept_emission(m)].into_iter().flatten() {
                let key = (tref.texture, tref.wrap.map(|w| w as u8));
                if base_textures.contains_key(&key) {
                    continue;
                }
                let tex = &scene.textures[tref.texture as usize];
                let (w, h) = tex.size();
                let rgb: Vec<u8> =
                    tex.texels().iter().flat_map(|t| t.map(|c| (255.0 * super::srgb_oetf(c as f64).clamp(0.0, 1.0)).round() as u8)).collect();
                let png = super::png::encode_rgb8(w, h, &rgb)?;
                let idx = push_png_texture(&mut root, &mut buf, &tex.name, &png, tref.wrap, true);
                base_textures.insert(key, idx);
            }
        }
    }

    // Materials used, in scene order. `MOZ_lightmap` objects by material index, added to
    // the JSON at the end (gltf-json's typed materials have no field for it).
    let mut moz_materials: Vec<(usize, serde_json::Value)> = Vec::new();
    let mut mat_index: BTreeMap<u32, json::Index<json::Material>> = BTreeMap::new();
    for &(_, m) in parts.keys() {
        if mat_index.contains_key(&m) {
            continue;
        }
        let mat = &scene.materials[m as usize];
        let emissive = (mat.emission * opts.exposure).min(Rgb::ONE);
        let extras = serde_json::json!({ "radiosity": {
            "reflectance": mat.reflectance.to_array(), "emission": mat.emission.to_array()
        }});
        let extras = Some(serde_json::value::to_raw_value(&extras).map_err(|e| Error::Invalid(e.to_string()))?);
        let material = match (lightmap_texture, moz) {
            (Some(tex), Some(lm)) => {
                let (factor, base_color_texture) = match &mat.base_texture {
                    Some((tref, factor)) => (
                        *factor,
                        Some(json::texture::Info {
                            index: base_textures[&(tref.texture, tref.wrap.map(|w| w as u8))],
                            tex_coord: 0,
                            extensions: None,
                            extras: Default::default(),
                        }),
                    ),
                    None => (mat.reflectance, None),
                };
                moz_materials.push((root.materials.len(), serde_json::json!({ "index": tex.value(), "texCoord": 1, "intensity": lm.intensity })));
                // An emission texture on the same coordinates: kept, its factor × exposure
                // (clipped to 1) as the emissive factor.
                let (emissive, emissive_texture) = match (kept_emission(mat), &mat.emission_texture) {
                    (Some(tref), Some((_, factor))) => (
                        (*factor * opts.exposure).min(Rgb::ONE),
                        Some(json::texture::Info {
                            index: base_textures[&(tref.texture, tref.wrap.map(|w| w as u8))],
                            tex_coord: 0,
                            extensions: None,
                            extras: Default::default(),
                        }),
                    ),
                    _ => (emissive, None),
                };
                json::Material {
                    name: Some(mat.name.clone()),
                    pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                        base_color_factor: json::material::PbrBaseColorFactor([factor.x as f32, factor.y as f32, factor.z as f32, 1.0]),
                        base_color_texture,
                        metallic_factor: json::material::StrengthFactor(0.0),
                        roughness_factor: json::material::StrengthFactor(1.0),
                        ..Default::default()
                    },
                    emissive_factor: json::material::EmissiveFactor([emissive.x as f32, emissive.y as f32, emissive.z as f32]),
                    emissive_texture,
                    double_sided: false,
                    extras,
                    ..Default::default()
                }
            }
            (None, _) => json::Material {
                name: Some(mat.name.clone()),
                pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                    base_color_factor: json::material::PbrBaseColorFactor([1.0; 4]),
                    metallic_factor: json::material::StrengthFactor(0.0),
                    roughness_factor: json::material::StrengthFactor(1.0),
                    ..Default::default()
                },
                emissive_factor: json::material::EmissiveFactor([emissive.x as f32, emissive.y as f32, emissive.z as f32]),
                double_sided: false,
                extras,
                extensions: Some(json::extensions::material::Material {
                    unlit: Some(json::extensions::material::Unlit {}),
                    ..Default::default()
                }),
                ..Default::default()
            },
            (Some(tex), None) => json::Material {
                name: Some(mat.name.clone()),
                pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                    base_color_factor: json::material::PbrBaseColorFactor([0.0, 0.0, 0.0, 1.0]),
                    metallic_factor: json::material::StrengthFactor(0.0),
                    roughness_factor: json::material::StrengthFactor(1.0),
                    ..Default::default()
                },
                emissive_factor: json::material::EmissiveFactor([1.0; 3]),
                emissive_texture: Some(json::texture::Info { index: tex, tex_coord: 1, extensions: None, extras: Default::default() }),
                double_sided: false,
                extras,
                ..Default::default()
            },
        };
        let idx = root.push(material);
        mat_index.insert(m, idx);
    }

    // Objects of a glTF input go back into their nodes: positions and normals in the node's
    // own frame (p = W⁻¹·x, n ∝ Wᵀ·n), and the winding reversed under a mirroring
    // transform, which viewers reverse again.
    let tree = scene.node_tree.as_deref().filter(|t| t.object_nodes.len() <= scene.objects.len());
    let frame = |object: u32| -> Option<(glam::DMat4, DMat3, bool)> {
        let t = tree?;
        let w = t.nodes[*t.object_nodes.get(object as usize)? as usize].world;
        let inv = w.inverse();
        inv.is_finite().then(|| (inv, DMat3::from_mat4(w).transpose(), w.determinant() < 0.0))
    };
    let mut meshes: BTreeMap<u32, Vec<json::mesh::Primitive>> = BTreeMap::new();
    for ((object, m), part) in &parts {
        let local = frame(*object);
        let pos: Vec<[f32; 3]> = part
            .vertices
            .iter()
            .map(|&v| {
                let x = mesh.positions[v as usize];
                local.map_or(x, |(inv, _, _)| inv.transform_point3(x)).as_vec3().to_array()
            })
            .collect();
        let nor: Vec<[f32; 3]> =
            part.normals.iter().map(|n| local.map_or(*n, |(_, nt, _)| (nt * *n).normalize_or_zero()).as_vec3().to_array()).collect();
        let flipped: Vec<u32>;
        let indices = match local {
            Some((_, _, true)) => {
                flipped = part.indices.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
                &flipped
            }
            _ => &part.indices,
        };
        let col: Vec<[f32; 3]> = part
            .vertices
            .iter()
            .map(|&v| {
                let l = vertex_b[v as usize].max(Rgb::ZERO) * (opts.exposure / std::f64::consts::PI);
                if moz.is_none() {
                    stats.clipped += l.to_array().iter().filter(|x| **x > 1.0).count();
                }
                l.min(Rgb::ONE).as_vec3().to_array()
            })
            .collect();
        let vec3 = json::accessor::Type::Vec3;
        let a_pos = buf.push_f32(&pos, vec3, true);
        let a_nor = buf.push_f32(&nor, vec3, false);
        // MOZ_lightmap: no vertex colours (three.js would multiply the light in twice).
        let a_col = moz.is_none().then(|| buf.push_f32(&col, vec3, false));
        let a_idx = buf.push_u32(indices);
        // TEXCOORD_0: the base-colour texture's coordinates (MOZ_lightmap, textured
        // materials: the polygon's map of its coordinate set, the texture transform
        // applied), else each chart's own planar coordinates in scene units (a texture
        // space with no seams inside a chart); TEXCOORD_1: the lightmap atlas.
        let mat = &scene.materials[*m as usize];
        let base_tex = moz.and(mat.base_texture.as_ref().map(|(t, _)| t).or(kept_emission(mat)));
        let uvs = lightmap.map(|lm| {
            let atlas = lm.atlas;
            let (uv0, uv1): (Vec<[f32; 2]>, Vec<[f32; 2]>) = part
                .vertices
                .iter()
                .zip(&part.patches)
                .map(|(&v, &p)| {
                    let x = mesh.positions[v as usize];
                    let q = match base_tex.and_then(|t| scene.polygons[p as usize].uv.get(t.tex_coord as usize).map(|map| (t, map))) {
                        Some((t, map)) => {
                            let uv = map.at(x);
                            let [a, b] = t.transform;
                            glam::DVec2::new(a[0] * uv.x + a[1] * uv.y + a[2], b[0] * uv.x + b[1] * uv.y + b[2])
                        }
                        None => atlas.frames[p as usize].at(x),
                    };
                    let (u, w) = atlas.uv(p, x);
                    ([q.x as f32, q.y as f32], [u as f32, w as f32])
                })
                .unzip();
            let vec2 = json::accessor::Type::Vec2;
            (buf.push_f32(&uv0, vec2, false), buf.push_f32(&uv1, vec2, false))
        });
        stats.vertices += pos.len();
        stats.triangles += part.indices.len() / 3;
        let mut attributes = BTreeMap::new();
        attributes.insert(Valid(json::mesh::Semantic::Positions), a_pos);
        attributes.insert(Valid(json::mesh::Semantic::Normals), a_nor);
        if let Some(a_col) = a_col {
            attributes.insert(Valid(json::mesh::Semantic::Colors(0)), a_col);
        }
        if let Some((a0, a1)) = uvs {
            attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), a0);
            attributes.insert(Valid(json::mesh::Semantic::TexCoords(1)), a1);
        }
        meshes.entry(*object).or_default().push(json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(a_idx),
            material: Some(mat_index[m]),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        });
    }
    let mut scene_nodes = Vec::new();
    // The input's node tree first (names, local transforms, children), its objects' meshes
    // on their nodes; other objects as nodes of their own at the root.
    let mut tree_nodes: Vec<json::Index<json::Node>> = Vec::new();
    if let Some(t) = tree {
        for n in &t.nodes {
            let matrix = (n.local != glam::DMat4::IDENTITY).then(|| n.local.as_mat4().to_cols_array());
            let idx = root.push(json::Node { name: n.name.clone(), matrix, ..Default::default() });
            match n.parent {
                Some(p) => {
                    let parent = &mut root.nodes[tree_nodes[p as usize].value()];
                    parent.children.get_or_insert_with(Vec::new).push(idx);
                }
                None => scene_nodes.push(idx),
            }
            tree_nodes.push(idx);
        }
    }
    for (object, primitives) in meshes {
        let name = scene.objects[object as usize].name.clone();
        let mesh_idx = root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(name.clone()),
            primitives,
            weights: None,
        });
        match tree.and_then(|t| t.object_nodes.get(object as usize)).filter(|_| frame(object).is_some()) {
            Some(&n) => root.nodes[tree_nodes[n as usize].value()].mesh = Some(mesh_idx),
            None => scene_nodes.push(root.push(json::Node { mesh: Some(mesh_idx), name: Some(name), ..Default::default() })),
        }
    }
    if let Some(c) = &opts.camera {
        let diag = scene.diagonal().max(f64::MIN_POSITIVE);
        // The near plane as far out as the scene allows: depth precision falls with
        // far/near, and a lamp 0.1 mm below the Cornell box's ceiling z-fights at near = 1 mm.
        let (lo, hi) = scene.bounds();
        let outside = (lo - c.position).max(c.position - hi).max(DVec3::ZERO).length();
        let znear = (1e-3 * diag).max(0.9 * outside);
        let cam = root.push(json::Camera {
            name: Some("camera".into()),
            orthographic: None,
            perspective: Some(json::camera::Perspective {
                aspect_ratio: None,
                yfov: c.vfov_deg.to_radians() as f32,
                zfar: Some((2.0 * diag + (c.position - scene_center(scene)).length()) as f32),
                znear: znear as f32,
                extensions: None,
                extras: Default::default(),
            }),
            type_: Valid(json::camera::Type::Perspective),
            extensions: None,
            extras: Default::default(),
        });
        let q = camera_rotation(c);
        scene_nodes.push(root.push(json::Node {
            camera: Some(cam),
            name: Some("camera".into()),
            rotation: Some(json::scene::UnitQuaternion([q.x as f32, q.y as f32, q.z as f32, q.w as f32])),
            translation: Some(c.position.as_vec3().to_array()),
            ..Default::default()
        }));
    }
    let s = root.push(json::Scene { extensions: None, extras: Default::default(), name: Some(scene.name.clone()), nodes: scene_nodes });
    root.scene = Some(s);
    while buf.bytes.len() % 4 != 0 {
        buf.bytes.push(0);
    }
    root.buffers.push(json::Buffer {
        byte_length: USize64::from(buf.bytes.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    root.buffer_views = buf.views;
    root.accessors = buf.accessors;
    let mut json_bytes = root.to_vec().map_err(|e| Error::Invalid(format!("glTF JSON: {e}")))?;
    if !moz_materials.is_empty() {
        let bad = |e: serde_json::Error| Error::Invalid(format!("glTF JSON: {e}"));
        let mut v: serde_json::Value = serde_json::from_slice(&json_bytes).map_err(bad)?;
        for (i, ext) in moz_materials {
            let m = &mut v["materials"][i];
            if !m.get("extensions").is_some_and(|e| e.is_object()) {
                m["extensions"] = serde_json::json!({});
            }
            m["extensions"]["MOZ_lightmap"] = ext;
        }
        json_bytes = serde_json::to_vec(&v).map_err(bad)?;
    }
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
        json: std::borrow::Cow::Owned(json_bytes),
        bin: Some(std::borrow::Cow::Owned(buf.bytes)),
    };
    let bytes = glb.to_vec().map_err(|e| Error::Invalid(format!("GLB: {e}")))?;
    Ok((bytes, stats))
}

/// Under `MOZ_lightmap`, the emission texture that is written with a material: one on the
/// base-colour texture's coordinates (set and transform), or any when there is no
/// base-colour texture (it then gives `TEXCOORD_0`). Others are shown by their mean.
fn kept_emission(m: &crate::scene::Material) -> Option<&crate::scene::TextureRef> {
    let (e, _) = m.emission_texture.as_ref()?;
    match &m.base_texture {
        None => Some(e),
        Some((b, _)) if b.tex_coord == e.tex_coord && b.transform == e.transform => Some(e),
        Some(_) => None,
    }
}

/// A PNG image stored in the buffer, with a linear-filtered sampler of the given wrap
/// modes (mipmapped when `mipmaps`), as a glTF texture.
fn push_png_texture(
    root: &mut json::Root,
    buf: &mut Buffer,
    name: &str,
    png: &[u8],
    wrap: [crate::scene::Wrap; 2],
    mipmaps: bool,
) -> json::Index<json::Texture> {
    let offset = buf.bytes.len();
    buf.bytes.extend_from_slice(png);
    let view = json::Index::push(
        &mut buf.views,
        json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(png.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: Some(name.into()),
            target: None,
            extensions: None,
            extras: Default::default(),
        },
    );
    while buf.bytes.len() % 4 != 0 {
        buf.bytes.push(0);
    }
    let image = root.push(json::Image {
        buffer_view: Some(view),
        mime_type: Some(json::image::MimeType("image/png".into())),
        name: Some(name.into()),
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    let mode = |w: crate::scene::Wrap| {
        Valid(match w {
            crate::scene::Wrap::Repeat => json::texture::WrappingMode::Repeat,
            crate::scene::Wrap::ClampToEdge => json::texture::WrappingMode::ClampToEdge,
            crate::scene::Wrap::MirroredRepeat => json::texture::WrappingMode::MirroredRepeat,
        })
    };
    let min = if mipmaps { json::texture::MinFilter::LinearMipmapLinear } else { json::texture::MinFilter::Linear };
    let sampler = root.push(json::texture::Sampler {
        mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
        min_filter: Some(Valid(min)),
        name: None,
        wrap_s: mode(wrap[0]),
        wrap_t: mode(wrap[1]),
        extensions: None,
        extras: Default::default(),
    });
    root.push(json::Texture { name: Some(name.into()), sampler: Some(sampler), source: image, extensions: None, extras: Default::default() })
}

fn scene_center(scene: &Scene) -> DVec3 {
    let (lo, hi) = scene.bounds();
    0.5 * (lo + hi)
}
