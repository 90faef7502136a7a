//! glTF 2.0 reader: `.gltf` (JSON, with external `.bin` files or base64 `data:` URIs) and
//! `.glb` (binary container).
//!
//! **What is read.** The default scene (else the first; a file without scenes draws every
//! root node), its full node hierarchy with each node's matrix or TRS transform, and the
//! triangles of every mesh primitive drawn as `TRIANGLES`, `TRIANGLE_STRIP` or
//! `TRIANGLE_FAN` (converted to triangles as the specification orders them), indexed or not.
//! Each triangle becomes one [`PolygonDesc`] whose vertex order is the file's: glTF front
//! faces are counter-clockwise, which is our right-hand rule. A node whose world matrix has a
//! negative determinant (a mirror) has its triangles reversed so that the front side stays
//! the front side. One [`ObjectDesc`] per node that draws a mesh, named after the node, else
//! the mesh, else `node<k>`. The first perspective camera met in the hierarchy becomes the
//! scene's [`Camera`] (position, look along −Z of the node, up +Y, `vfov_deg` = `yfov`).
//!
//! **Materials.** Every surface is a Lambertian reflector: reflectance ρ =
//! `baseColorFactor` RGB (linear, as glTF specifies), emitted radiance L_e =
//! `emissiveFactor` × `KHR_materials_emissive_strength.emissiveStrength`; `doubleSided`
//! gives a two-sided material. Only materials used by a drawn primitive are kept. A
//! negative `baseColorFactor` channel is an error naming the file, the JSON line of the
//! material (for `.gltf`) and the material; a channel ≥ 1 is lowered by validation to
//! [`super::MAX_REFLECTANCE`] with one warning (refused in strict mode). glTF's *default*
//! `baseColorFactor` is 1.0,
//! which a radiosity solver cannot use (a surface that reflects everything never absorbs,
//! and the solution diverges in a closed room): a material that omits it, and a primitive
//! without a material, get reflectance [`DEFAULT_REFLECTANCE`] (0.8, Blender's default base
//! colour) and a [`Warning`] naming the material — unless it has a `baseColorTexture`, whose
//! factor defaults to 1.0 as glTF says. **Textures**: `baseColorTexture` and
//! `emissiveTexture` (PNG or JPEG images, by `uri` — relative file or base64 `data:` — or
//! `bufferView`) multiply the factors, read through `TEXCOORD_n` (`texCoord`, or
//! `KHR_texture_transform`'s override), the transform and the sampler's wrap modes (see
//! [`super::texture`]); a texture whose only source is an extension's (WebP, KTX2) is
//! ignored with a warning, an image that cannot be read or decoded is an error. Metallic/
//! roughness, alpha, normal maps and vertex colours are ignored.
//!
//! **Lights.** `KHR_lights_punctual` point, spot and directional lights become
//! [`super::Light`]s at their nodes' world positions, pointing along the node's −Z (scale
//! ignored, as the extension says), with intensity `color × intensity` taken in the
//! scene's radiometric units (candela as radiant intensity, lux as irradiance; no
//! 683 lm/W); spots keep `innerConeAngle`/`outerConeAngle` and glTF's falloff. `range` is
//! ignored with a warning: light falls off as 1/r², as it physically does. A light of
//! another type is ignored with a warning (counted in [`SceneDesc::ignored_lights`]).
//!
//! **Not supported.** Points and lines (skipped with a warning: they have no area), skins
//! and morph targets (the rest pose is used, with a warning), orthographic cameras
//! (ignored), URLs other than relative file paths and `data:` URIs, and required
//! extensions that change geometry (Draco, meshopt, GPU instancing: an error).
//!
//! **Robustness.** The file's JSON is read with `gltf::json` types, but buffers and
//! accessors are read here with checked arithmetic instead of the crate's `import`/reader
//! (which is off: no image dependency) and without its validator (which indexes the
//! accessor array before checking the index, and rejects files that lack the optional
//! POSITION `min`/`max`). Every index, offset, stride and count is checked, the node graph
//! may not contain cycles, so a malformed file is an [`Error`] naming the file (and, for
//! `.gltf`, the JSON line of the offending array element), never a panic.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{DMat4, DQuat, DVec2, DVec3};
use gltf::json::{
    self,
    accessor::{ComponentType, Type},
    mesh::{Mode, Semantic},
    validation::Checked,
};

use super::{Camera, MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
use crate::{Error, Location, Result, Rgb, Warning};

/// Reflectance given to materials without `baseColorFactor` and to primitives without a
/// material (glTF's own default, 1.0, is not physical for radiosity).
pub const DEFAULT_REFLECTANCE: f64 = 0.8;

/// Most elements an accessor without a buffer view (all zeros, maybe sparse) may have.
const MAX_ZERO_ACCESSOR: usize = 1 << 22;

/// Required extensions we can read.
const SUPPORTED_REQUIRED: [&str; 3] = ["KHR_materials_emissive_strength", "KHR_mesh_quantization", "KHR_texture_transform"];

/// Required extensions that only change looks we ignore anyway (textures, shading).
fn ignorable_extension(name: &str) -> bool {
    name.starts_with("KHR_materials_")
        || name.starts_with("KHR_texture_")
        || name.starts_with("EXT_texture_")
        || name == "MSFT_texture_dds"
        || name == "KHR_lights_punctual"
}

/// Reads a `.gltf` or `.glb` file (external buffers relative to its folder).
pub fn load_gltf(path: &Path) -> Result<SceneDesc> {
    let desc = read_gltf(path)?;
    check_base_colors(&desc.materials, path)?;
    Ok(desc)
}

/// Reads a glTF file without rejecting out-of-range `baseColorFactor`s, so that a TOML
/// scene file can override them first (see [`check_base_colors`]).
pub(crate) fn read_gltf(path: &Path) -> Result<SceneDesc> {
    let bytes = super::read_input_file(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    parse_gltf(&bytes, path, |rel| super::read_input(&dir.join(rel)))
}

/// The glTF-specific check of reflectances: a negative or non-finite `baseColorFactor`
/// channel is an error naming the material and where it is defined. (A channel ≥ 1, glTF's
/// default white, is lowered to [`super::MAX_REFLECTANCE`] by validation, or refused there
/// in strict mode.)
pub(crate) fn check_base_colors(materials: &[MaterialDesc], file: &Path) -> Result<()> {
    for m in materials {
        let r = m.reflectance.to_array();
        if r.iter().any(|c| !c.is_finite() || *c < 0.0) {
            return Err(Error::input(
                m.loc.clone().unwrap_or_else(|| Location::file(file)),
                format!(
                    "material '{}': baseColorFactor RGB {:?} has a negative or non-finite channel (lower it in \
                     the file, or override it in a TOML scene file: [materials.\"{}\"] reflectance = [r, g, b])",
                    m.name, r, m.name
                ),
            ));
        }
    }
    Ok(())
}

/// Parses the bytes of a `.gltf` (JSON) or `.glb` file. `file` names the source in errors;
/// `load_file(relative_path)` reads external buffers. Base colours are not range-checked
/// here (validation or [`load_gltf`] does it).
pub fn parse_gltf(
    bytes: &[u8],
    file: &Path,
    load_file: impl FnMut(&str) -> std::io::Result<Vec<u8>>,
) -> Result<SceneDesc> {
    let (json_bytes, blob, is_glb) = if bytes.starts_with(b"glTF") {
        let (j, b) = split_glb(bytes).map_err(|m| Error::input(Location::file(file), format!("invalid GLB file: {m}")))?;
        (j, b, true)
    } else if file.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb")) {
        return Err(Error::input(Location::file(file), "not a GLB file: it does not start with 'glTF'"));
    } else {
        (bytes, None, false)
    };
    let json_bytes = json_bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(json_bytes);
    let json_err = |e: serde_json::Error, what: &str| -> Error {
        if json_bytes.iter().all(|b| b.is_ascii_whitespace()) {
            return Error::input(Location::line(file, 1), "the file is empty");
        }
        // serde_json's message ends in " at line L column C"; the location says it already.
        let full = e.to_string();
        let text = match full.rfind(" at line ") {
            Some(i) => full[..i].to_string(),
            None => full,
        };
        let e_line = e.line();
        let e_col = e.column();
        if is_glb {
            Error::input(
                Location::file(file),
                format!("{what} in the GLB's JSON chunk (line {e_line}, column {e_col}): {text}"),
            )
        } else {
            Error::Input {
                loc: Location { file: file.into(), line: Some(e_line.max(1)), column: Some(e_col.max(1)) },
                msg: format!("{what}: {text}"),
            }
        }
    };
    let raw: serde_json::Value = serde_json::from_slice(json_bytes).map_err(|e| json_err(e, "invalid JSON"))?;
    match raw.get("asset").and_then(|a| a.get("version")).and_then(|v| v.as_str()) {
        Some(v) if v.starts_with("2.") => {}
        Some(v) => {
            return Err(Error::input(
                Location::file(file),
                format!("glTF version {v} is not supported (only glTF 2.x)"),
            ))
        }
        None => return Err(Error::input(Location::file(file), "not a glTF file: no \"asset\": {\"version\": ...}")),
    }
    let root: json::Root = match <json::Root as serde::Deserialize>::deserialize(&raw) {
        Ok(r) => r,
        // Deserialize again from the text to get the error's line and column.
        Err(e) => {
            return Err(match serde_json::from_slice::<json::Root>(json_bytes) {
                Err(located) => json_err(located, "invalid glTF"),
                Ok(_) => Error::input(Location::file(file), format!("invalid glTF: {e}")),
            })
        }
    };
    let text = if is_glb { None } else { std::str::from_utf8(json_bytes).ok() };
    let mut reader = Reader {
        file,
        lines: text.map(JsonLines::new),
        root: &root,
        raw: &raw,
        blob,
        buffers: vec![None; root.buffers.len()],
        load_file,
        warnings: Vec::new(),
        cur_mesh: 0,
        textures: Vec::new(),
        image_texture: HashMap::new(),
    };
    reader.read()
}

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
fn split_glb(bytes: &[u8]) -> std::result::Result<(&[u8], Option<&[u8]>), String> {
    let u32_at = |o: usize| -> Option<u32> {
        bytes.get(o..o.checked_add(4)?).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    };
    let (Some(version), Some(length)) = (u32_at(4), u32_at(8)) else {
        return Err(format!("truncated header ({} bytes)", bytes.len()));
    };
    if version != 2 {
        return Err(format!("container version {version} is not supported (only 2)"));
    }
    let length = length as usize;
    if length > bytes.len() {
        return Err(format!("truncated: the header says {length} bytes, the file has {}", bytes.len()));
    }
    let mut off = 12usize;
    let mut json: Option<&[u8]> = None;
    let mut bin: Option<&[u8]> = None;
    while off < length {
        let (Some(clen), Some(ctype)) = (u32_at(off), u32_at(off + 4)) else {
            return Err(format!("truncated chunk header at byte {off}"));
        };
        let start = off + 8;
        let end = start.checked_add(clen as usize).filter(|e| *e <= length).ok_or_else(|| {
            format!("chunk at byte {off} is {clen} bytes long but only {} remain", length.saturating_sub(start))
        })?;
        let data = &bytes[start..end];
        match ctype {
            0x4E4F_534A if json.is_none() => json = Some(data),
            0x004E_4942 if json.is_some() && bin.is_none() => bin = Some(data),
            0x4E4F_534A | 0x004E_4942 => return Err(format!("unexpected chunk at byte {off}")),
            _ => {} // unknown chunk types are skipped (specification)
        }
        if json.is_none() {
            return Err("the first chunk is not JSON".into());
        }
        off = end;
    }
    let json = json.ok_or("no JSON chunk")?;
    Ok((json, bin))
}

/// Byte offsets of the elements of the root object's arrays (`"meshes": [{..}, ..]`) and
/// line starts, to turn `meshes[3]` into a line number. Works on valid JSON only (it has
/// been parsed before).
struct JsonLines {
    elements: HashMap<String, Vec<usize>>,
    line_starts: Vec<usize>,
}

impl JsonLines {
    fn new(text: &str) -> JsonLines {
        let b = text.as_bytes();
        let mut elements: HashMap<String, Vec<usize>> = HashMap::new();
        let mut depth = 0usize;
        let mut key: Option<String> = None;
        let mut array_key: Option<String> = None;
        let mut expect = false;
        let mut i = 0;
        while i < b.len() {
            let c = b[i];
            if depth == 2 && expect && !c.is_ascii_whitespace() && c != b']' {
                if let Some(k) = &array_key {
                    elements.entry(k.clone()).or_default().push(i);
                }
                expect = false;
            }
            match c {
                b'"' => {
                    let start = i + 1;
                    i += 1;
                    while i < b.len() && b[i] != b'"' {
                        if b[i] == b'\\' {
                            i += 1;
                        }
                        i += 1;
                    }
                    if depth == 1 {
                        key = text.get(start..i.min(b.len())).map(str::to_string);
                    }
                }
                b'{' | b'[' => {
                    if depth == 1 && c == b'[' {
                        array_key = key.take();
                        expect = true;
                    }
                    depth += 1;
                }
                b'}' | b']' => {
                    depth = depth.saturating_sub(1);
                    if depth <= 1 {
                        array_key = None;
                        expect = false;
                    }
                }
                b',' if depth == 2 => expect = true,
                _ => {}
            }
            i += 1;
        }
        let line_starts = std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect();
        JsonLines { elements, line_starts }
    }

    /// 1-based line of `array[index]`.
    fn line(&self, array: &str, index: usize) -> Option<usize> {
        let off = *self.elements.get(array)?.get(index)?;
        Some(self.line_starts.partition_point(|&s| s <= off))
    }
}

/// Triangles of one mesh in its own frame, with the glTF material index of each.
struct MeshTris {
    tris: Vec<Tri>,
}

/// One triangle: positions, glTF material, texture coordinates per set (those the
/// material's textures use; empty without).
struct Tri {
    p: [DVec3; 3],
    material: Option<usize>,
    uv: Vec<[DVec2; 3]>,
}

/// One node that draws a mesh.
struct Instance {
    node: usize,
    mesh: usize,
    world: DMat4,
    /// Its node's place in the node tree.
    tree: u32,
}

struct Reader<'a, F> {
    file: &'a Path,
    lines: Option<JsonLines>,
    root: &'a json::Root,
    raw: &'a serde_json::Value,
    blob: Option<&'a [u8]>,
    buffers: Vec<Option<Vec<u8>>>,
    load_file: F,
    warnings: Vec<Warning>,
    /// The mesh being read (for the location of its errors).
    cur_mesh: usize,
    /// Decoded textures, and the texture each glTF image became.
    textures: Vec<std::sync::Arc<super::Texture>>,
    image_texture: HashMap<usize, u32>,
}

fn name_or(name: &Option<String>, fallback: impl FnOnce() -> String) -> String {
    match name {
        Some(n) if !n.trim().is_empty() => n.clone(),
        _ => fallback(),
    }
}

impl<F: FnMut(&str) -> std::io::Result<Vec<u8>>> Reader<'_, F> {
    /// The place of `array[index]`: the JSON line for `.gltf`, the file for `.glb`.
    fn at(&self, array: &str, index: usize) -> Location {
        match self.lines.as_ref().and_then(|l| l.line(array, index)) {
            Some(line) => Location::line(self.file, line),
            None => Location::file(self.file),
        }
    }

    fn err(&self, array: &str, index: usize, msg: impl Into<String>) -> Error {
        Error::input(self.at(array, index), msg)
    }

    fn warn(&mut self, loc: Location, msg: impl Into<String>) {
        self.warnings.push(Warning { loc: Some(loc), msg: msg.into() });
    }

    fn mesh_label(&self, m: usize) -> String {
        match self.root.meshes.get(m).and_then(|x| x.name.as_deref()) {
            Some(n) => format!("mesh '{n}' (meshes[{m}])"),
            None => format!("meshes[{m}]"),
        }
    }

    fn node_label(&self, n: usize) -> String {
        match self.root.nodes.get(n).and_then(|x| x.name.as_deref()) {
            Some(name) => format!("node '{name}' (nodes[{n}])"),
            None => format!("nodes[{n}]"),
        }
    }

    fn read(&mut self) -> Result<SceneDesc> {
        let root = self.root;
        for (i, ext) in root.extensions_required.iter().enumerate() {
            if SUPPORTED_REQUIRED.contains(&ext.as_str()) {
                continue;
            }
            if ignorable_extension(ext) {
                self.warn(Location::file(self.file), format!("required extension {ext} is ignored"));
            } else {
                return Err(Error::input(
                    Location::file(self.file),
                    format!("extensionsRequired[{i}]: extension {ext} is not supported"),
                ));
            }
        }

        let (instances, camera, light_nodes, tree) = self.traverse()?;

        // Triangles of each mesh drawn, in the mesh's frame.
        let mut meshes: HashMap<usize, MeshTris> = HashMap::new();
        for inst in &instances {
            if let std::collections::hash_map::Entry::Vacant(slot) = meshes.entry(inst.mesh) {
                slot.insert(self.mesh_triangles(inst.mesh)?);
            }
        }

        // Materials used, in file order; then the default material if a primitive has none.
        let mut used: Vec<usize> = meshes.values().flat_map(|m| m.tris.iter().filter_map(|t| t.material)).collect();
        used.sort_unstable();
        used.dedup();
        let mut desc = SceneDesc {
            name: self.file.file_stem().and_then(|s| s.to_str()).unwrap_or("scene").to_string(),
            ..Default::default()
        };
        let mut mat_map: HashMap<usize, u32> = HashMap::new();
        for &mi in &used {
            let m = self.material(mi)?;
            mat_map.insert(mi, desc.materials.len() as u32);
            desc.materials.push(m);
        }
        let needs_default = meshes.values().any(|m| m.tris.iter().any(|t| t.material.is_none()));
        let default_mat = if needs_default {
            self.warn(
                Location::file(self.file),
                format!("primitives without a material get a grey default material (reflectance {DEFAULT_REFLECTANCE})"),
            );
            desc.materials.push(MaterialDesc::diffuse("default", Rgb::splat(DEFAULT_REFLECTANCE)));
            (desc.materials.len() - 1) as u32
        } else {
            0
        };

        let mut object_nodes = Vec::with_capacity(instances.len());
        for inst in &instances {
            let node = &root.nodes[inst.node];
            let name = name_or(&node.name, || {
                name_or(&root.meshes[inst.mesh].name, || format!("node{}", inst.node))
            });
            let object = desc.objects.len() as u32;
            desc.objects.push(ObjectDesc { name, loc: Some(self.at("nodes", inst.node)) });
            object_nodes.push(inst.tree);
            let flip = inst.world.determinant() < 0.0;
            let mesh_loc = self.at("meshes", inst.mesh);
            for tri in &meshes[&inst.mesh].tris {
                let mut v: Vec<DVec3> = tri.p.iter().map(|p| inst.world.transform_point3(*p)).collect();
                if v.iter().any(|p| !p.is_finite()) {
                    return Err(self.err(
                        "nodes",
                        inst.node,
                        format!(
                            "{}: the transform of {} makes a vertex non-finite",
                            self.mesh_label(inst.mesh),
                            self.node_label(inst.node)
                        ),
                    ));
                }
                let mut uvs: Vec<Vec<DVec2>> = tri.uv.iter().map(|t| t.to_vec()).collect();
                if flip {
                    v.reverse();
                    uvs.iter_mut().for_each(|t| t.reverse());
                }
                let material = match tri.material {
                    Some(m) => mat_map[&m],
                    None => default_mat,
                };
                desc.polygons.push(PolygonDesc { uvs, vertices: v, material, object, loc: Some(mesh_loc.clone()) });
            }
        }
        if desc.polygons.is_empty() {
            return Err(Error::input(
                Location::file(self.file),
                format!(
                    "the scene draws no triangles ({} nodes, {} meshes in the file)",
                    root.nodes.len(),
                    root.meshes.len()
                ),
            ));
        }
        desc.camera = camera;
        desc.textures = std::mem::take(&mut self.textures);
        desc.node_tree = Some(std::sync::Arc::new(super::NodeTree { nodes: tree, object_nodes }));
        self.lights(&light_nodes, &mut desc)?;
        desc.warnings = std::mem::take(&mut self.warnings);
        Ok(desc)
    }

    /// The KHR_lights_punctual lights placed by `nodes` (node, light index, world matrix).
    fn lights(&mut self, nodes: &[(usize, usize, DMat4)], desc: &mut SceneDesc) -> Result<()> {
        use super::{Light, LightKind};
        let defs = self
            .raw
            .get("extensions")
            .and_then(|x| x.get("KHR_lights_punctual"))
            .and_then(|x| x.get("lights"))
            .and_then(|l| l.as_array())
            .cloned()
            .unwrap_or_default();
        let mut warned_range = false;
        for &(ni, li, world) in nodes {
            let loc = self.at("nodes", ni);
            let Some(def) = defs.get(li) else {
                return Err(self.err(
                    "nodes",
                    ni,
                    format!("{}: KHR_lights_punctual light {li} is out of range (there are {})", self.node_label(ni), defs.len()),
                ));
            };
            let file = self.file;
            let num = |v: Option<&serde_json::Value>, default: f64, what: &str| -> Result<f64> {
                match v {
                    None => Ok(default),
                    Some(x) => x.as_f64().ok_or_else(|| {
                        Error::input(Location::file(file), format!("KHR_lights_punctual light {li}: {what} {x} is not a number"))
                    }),
                }
            };
            let name = def.get("name").and_then(|n| n.as_str()).map_or_else(|| format!("light {li}"), str::to_string);
            let color = match def.get("color") {
                None => [1.0; 3],
                Some(c) => match c.as_array().map(|a| a.iter().filter_map(|x| x.as_f64()).collect::<Vec<f64>>()) {
                    Some(v) if v.len() == 3 => [v[0], v[1], v[2]],
                    _ => return Err(self.err("nodes", ni, format!("light '{name}': color {c} is not three numbers"))),
                },
            };
            let intensity = Rgb::from_array(color) * num(def.get("intensity"), 1.0, "intensity")?;
            if def.get("range").is_some() && !warned_range {
                warned_range = true;
                self.warn(loc.clone(), format!("light '{name}': range is ignored (light falls off as 1/r², physically)"));
            }
            let position = world.transform_point3(DVec3::ZERO);
            let direction = world.transform_vector3(-DVec3::Z);
            let kind = match def.get("type").and_then(|t| t.as_str()) {
                Some("point") => LightKind::Point { position },
                Some("directional") => LightKind::Directional { direction },
                Some("spot") => {
                    let spot = def.get("spot");
                    LightKind::Spot {
                        position,
                        direction,
                        inner_cone: num(spot.and_then(|s| s.get("innerConeAngle")), 0.0, "innerConeAngle")?,
                        outer_cone: num(spot.and_then(|s| s.get("outerConeAngle")), std::f64::consts::FRAC_PI_4, "outerConeAngle")?,
                    }
                }
                other => {
                    let t = other.map_or_else(|| "none".to_string(), |t| format!("\"{t}\""));
                    let msg = format!("light '{name}' of type {t} is ignored (KHR_lights_punctual has point, spot, directional)");
                    self.warn(loc, msg.clone());
                    desc.ignored_lights.push(format!("{}: {msg}", self.file.display()));
                    continue;
                }
            };
            desc.lights.push(Light { name, kind, intensity, loc: Some(loc) });
        }
        Ok(())
    }

    /// Walks the scene's node hierarchy: nodes that draw a mesh with their world matrices,
    /// the first perspective camera, and the nodes that place a KHR_lights_punctual light
    /// (node, light, world matrix).
    #[allow(clippy::type_complexity)]
    /// The instances to draw, the first camera, the punctual lights' (node, light, world)
    /// and the node tree reached (parents first; `Instance::tree` indexes it).
    #[allow(clippy::type_complexity)]
    fn traverse(&mut self) -> Result<(Vec<Instance>, Option<Camera>, Vec<(usize, usize, DMat4)>, Vec<super::SceneNode>)> {
        let root = self.root;
        let roots: Vec<usize> = if root.scenes.is_empty() {
            // No scene: every node that is nobody's child.
            let mut child = vec![false; root.nodes.len()];
            for n in &root.nodes {
                for c in n.children.iter().flatten() {
                    if let Some(f) = child.get_mut(c.value()) {
                        *f = true;
                    }
                }
            }
            (0..root.nodes.len()).filter(|&i| !child[i]).collect()
        } else {
            let si = root.scene.map(|s| s.value()).unwrap_or(0);
            let Some(scene) = root.scenes.get(si) else {
                return Err(Error::input(
                    Location::file(self.file),
                    format!("\"scene\": {si} is out of range (there are {} scenes)", root.scenes.len()),
                ));
            };
            scene.nodes.iter().map(|n| n.value()).collect()
        };

        let mut instances = Vec::new();
        let mut lights = Vec::new();
        let mut camera: Option<Camera> = None;
        let mut visited: HashSet<usize> = HashSet::new();
        let mut warned_skin = false;
        let mut tree: Vec<super::SceneNode> = Vec::new();
        // (node, parent's world, parent node, parent's place in `tree`)
        let mut stack: Vec<(usize, DMat4, Option<usize>, Option<u32>)> =
            roots.iter().rev().map(|&n| (n, DMat4::IDENTITY, None, None)).collect();
        while let Some((ni, parent, from, parent_t)) = stack.pop() {
            let Some(node) = root.nodes.get(ni) else {
                let msg = format!("node index {ni} is out of range (there are {} nodes)", root.nodes.len());
                return Err(match from {
                    Some(p) => self.err("nodes", p, format!("{}: child {msg}", self.node_label(p))),
                    None => Error::input(Location::file(self.file), format!("scene: {msg}")),
                });
            };
            if !visited.insert(ni) {
                return Err(self.err(
                    "nodes",
                    ni,
                    format!("{} is reached twice: the node hierarchy must be a tree (no cycles, one parent)", self.node_label(ni)),
                ));
            }
            let local = self.local_matrix(ni)?;
            let world = parent * local;
            let here_t = tree.len() as u32;
            tree.push(super::SceneNode { name: node.name.clone(), local, world, parent: parent_t });
            if let Some(m) = node.mesh {
                let mi = m.value();
                if mi >= root.meshes.len() {
                    return Err(self.err(
                        "nodes",
                        ni,
                        format!("{}: mesh {mi} is out of range (there are {} meshes)", self.node_label(ni), root.meshes.len()),
                    ));
                }
                let morphs = root.meshes[mi].primitives.iter().any(|p| p.targets.as_ref().is_some_and(|t| !t.is_empty()));
                if (node.skin.is_some() || morphs) && !warned_skin {
                    warned_skin = true;
                    self.warn(self.at("nodes", ni), "skins and morph targets are ignored: meshes are read in their rest pose");
                }
                instances.push(Instance { node: ni, mesh: mi, world, tree: here_t });
            }
            let light = self.raw.get("nodes").and_then(|n| n.get(ni)).and_then(|n| n.get("extensions")).and_then(|x| x.get("KHR_lights_punctual"));
            if let Some(l) = light {
                match l.get("light").and_then(|i| i.as_u64()) {
                    Some(li) => lights.push((ni, li as usize, world)),
                    None => {
                        return Err(self.err("nodes", ni, format!("{}: KHR_lights_punctual has no light index", self.node_label(ni))))
                    }
                }
            }
            if let (None, Some(c)) = (&camera, node.camera) {
                camera = self.camera(ni, c.value(), world);
            }
            for c in node.children.iter().flatten().rev() {
                stack.push((c.value(), world, Some(ni), Some(here_t)));
            }
        }
        Ok((instances, camera, lights, tree))
    }

    /// A node's own transform: its matrix, or translation × rotation × scale.
    fn local_matrix(&self, ni: usize) -> Result<DMat4> {
        let node = &self.root.nodes[ni];
        let f = |a: &[f32]| a.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
        let m = match node.matrix {
            Some(m) => {
                let v = f(&m);
                let mut a = [0.0; 16];
                a.copy_from_slice(&v);
                DMat4::from_cols_array(&a)
            }
            None => {
                let t = node.translation.map(|t| DVec3::from_slice(&f(&t))).unwrap_or(DVec3::ZERO);
                let s = node.scale.map(|s| DVec3::from_slice(&f(&s))).unwrap_or(DVec3::ONE);
                let r = match &node.rotation {
                    Some(q) => {
                        let q = DQuat::from_slice(&f(&q.0));
                        let len = q.length();
                        if !(len.is_finite() && len > 0.0) {
                            return Err(self.err(
                                "nodes",
                                ni,
                                format!("{}: rotation {:?} is not a unit quaternion", self.node_label(ni), q.to_array()),
                            ));
                        }
                        q / len
                    }
                    None => DQuat::IDENTITY,
                };
                DMat4::from_scale_rotation_translation(s, r, t)
            }
        };
        if !m.is_finite() {
            return Err(self.err("nodes", ni, format!("{}: the transform has a non-finite value", self.node_label(ni))));
        }
        Ok(m)
    }

    /// The glTF perspective camera `ci` seen through node `ni`, or None (with a warning).
    fn camera(&mut self, ni: usize, ci: usize, world: DMat4) -> Option<Camera> {
        let root = self.root;
        let loc = self.at("nodes", ni);
        let Some(cam) = root.cameras.get(ci) else {
            self.warn(loc, format!("camera {ci} is out of range; ignored"));
            return None;
        };
        let Some(p) = &cam.perspective else {
            self.warn(self.at("cameras", ci), "only perspective cameras are used; this one is ignored");
            return None;
        };
        let position = world.transform_point3(DVec3::ZERO);
        let forward = world.transform_vector3(-DVec3::Z);
        let c = Camera {
            position,
            look_at: position + forward.normalize_or_zero(),
            up: world.transform_vector3(DVec3::Y),
            vfov_deg: f64::from(p.yfov).to_degrees(),
        };
        match c.validate() {
            Ok(()) => Some(c),
            Err(m) => {
                self.warn(self.at("cameras", ci), format!("camera ignored: {m}"));
                None
            }
        }
    }

    /// The material `mi` as a description (reflectance not range-checked here).
    fn material(&mut self, mi: usize) -> Result<MaterialDesc> {
        let root = self.root;
        let m = &root.materials[mi];
        let name = name_or(&m.name, || format!("material{mi}"));
        let loc = self.at("materials", mi);
        let raw_m = self.raw.get("materials").and_then(|a| a.get(mi));
        let pbr = raw_m.and_then(|m| m.get("pbrMetallicRoughness"));
        let has_base = pbr.and_then(|p| p.get("baseColorFactor")).is_some();
        let base_texture = match pbr.and_then(|p| p.get("baseColorTexture")) {
            Some(info) => self.texture_ref(info, mi, &name, "baseColorTexture")?,
            None => None,
        };
        let emission_texture = match raw_m.and_then(|m| m.get("emissiveTexture")) {
            Some(info) => self.texture_ref(info, mi, &name, "emissiveTexture")?,
            None => None,
        };
        // With a texture, glTF's default factor 1.0 is the normal case: the texture is the colour.
        let reflectance = if has_base || base_texture.is_some() {
            let c = m.pbr_metallic_roughness.base_color_factor.0;
            Rgb::new(c[0].into(), c[1].into(), c[2].into())
        } else {
            self.warn(
                loc.clone(),
                format!(
                    "material '{name}' has no baseColorFactor (glTF's default 1.0 would never absorb light): \
                     using reflectance {DEFAULT_REFLECTANCE}"
                ),
            );
            Rgb::splat(DEFAULT_REFLECTANCE)
        };
        let e = m.emissive_factor.0;
        let strength = m
            .extensions
            .as_ref()
            .and_then(|x| x.emissive_strength.as_ref())
            .map(|s| f64::from(s.emissive_strength.0))
            .unwrap_or(1.0);
        let emission = Rgb::new(e[0].into(), e[1].into(), e[2].into()) * strength;
        Ok(MaterialDesc { name, reflectance, emission, two_sided: m.double_sided.then_some(true), loc: Some(loc), base_texture, emission_texture, thermal: None })
    }

    /// The texture-coordinate sets material `mi`'s textures read (from the raw JSON:
    /// `texCoord`, or `KHR_texture_transform`'s override).
    fn material_tex_coords(&self, mi: usize) -> Vec<usize> {
        let Some(m) = self.raw.get("materials").and_then(|a| a.get(mi)) else {
            return Vec::new();
        };
        let infos = [m.get("pbrMetallicRoughness").and_then(|p| p.get("baseColorTexture")), m.get("emissiveTexture")];
        let mut sets: Vec<usize> = infos.iter().flatten().map(|i| tex_coord_of(i) as usize).collect();
        sets.sort_unstable();
        sets.dedup();
        sets
    }

    /// A material's `textureInfo` as a [`super::TextureRef`], decoding its image on first use.
    /// None (with a warning) for a texture whose image is only in an unsupported extension.
    fn texture_ref(&mut self, info: &serde_json::Value, mi: usize, mat: &str, what: &str) -> Result<Option<super::TextureRef>> {
        let raw = self.raw;
        let err = |s: &Self, msg: String| s.err("materials", mi, format!("material '{mat}': {what}: {msg}"));
        let Some(ti) = info.get("index").and_then(|v| v.as_u64()).map(|v| v as usize) else {
            return Err(err(self, "no texture index".into()));
        };
        let Some(tex) = raw.get("textures").and_then(|a| a.get(ti)) else {
            return Err(err(self, format!("texture {ti} does not exist")));
        };
        let Some(image) = tex.get("source").and_then(|v| v.as_u64()).map(|v| v as usize) else {
            self.warn(
                self.at("textures", ti),
                format!(
                    "material '{mat}': {what}: texture {ti} has no PNG/JPEG source (only an extension's image, \
                     e.g. WebP or KTX2); the material's factor is used alone"
                ),
            );
            return Ok(None);
        };
        let mut wrap = [super::Wrap::Repeat; 2];
        if let Some(si) = tex.get("sampler").and_then(|v| v.as_u64()) {
            let Some(sampler) = raw.get("samplers").and_then(|a| a.get(si as usize)) else {
                return Err(err(self, format!("texture {ti}: sampler {si} does not exist")));
            };
            for (k, key) in ["wrapS", "wrapT"].iter().enumerate() {
                if let Some(code) = sampler.get(*key).and_then(|v| v.as_u64()) {
                    wrap[k] = super::Wrap::from_gltf(code as u32)
                        .ok_or_else(|| err(self, format!("sampler {si}: {key} {code} is not a glTF wrap mode")))?;
                }
            }
        }
        let texture = self.image_texture(image, ti)?;
        let mut tref = super::TextureRef::new(texture, tex_coord_of(info));
        tref.wrap = wrap;
        if let Some(t) = info.get("extensions").and_then(|x| x.get("KHR_texture_transform")) {
            let pair = |key: &str, d: [f64; 2]| -> [f64; 2] {
                t.get(key)
                    .and_then(|v| v.as_array())
                    .filter(|a| a.len() == 2)
                    .map(|a| [a[0].as_f64().unwrap_or(d[0]), a[1].as_f64().unwrap_or(d[1])])
                    .unwrap_or(d)
            };
            let rotation = t.get("rotation").and_then(|v| v.as_f64()).unwrap_or(0.0);
            tref = tref.with_transform(pair("offset", [0.0, 0.0]), rotation, pair("scale", [1.0, 1.0]));
            if tref.transform.iter().flatten().any(|c| !c.is_finite()) {
                return Err(err(self, "KHR_texture_transform has a non-finite value".into()));
            }
        }
        Ok(Some(tref))
    }

    /// The scene texture of glTF image `ii` (decoded on first use).
    fn image_texture(&mut self, ii: usize, ti: usize) -> Result<u32> {
        if let Some(&t) = self.image_texture.get(&ii) {
            return Ok(t);
        }
        let raw = self.raw;
        let fail = |s: &Self, msg: String| s.err("images", ii, format!("image {ii}: {msg}"));
        let Some(img) = raw.get("images").and_then(|a| a.get(ii)) else {
            return Err(self.err("textures", ti, format!("texture {ti}: image {ii} does not exist")));
        };
        let label = img.get("name").and_then(|v| v.as_str()).map(str::to_string);
        let (bytes, name): (Vec<u8>, String) = if let Some(uri) = img.get("uri").and_then(|v| v.as_str()) {
            if uri.starts_with("data:") {
                let Some(pos) = uri.find(";base64,") else {
                    return Err(fail(self, "only base64 data: URIs are supported".into()));
                };
                let bytes = base64::engine::general_purpose::STANDARD
                    .decode(uri[pos + 8..].trim_end())
                    .map_err(|e| fail(self, format!("invalid base64 data: {e}")))?;
                (bytes, label.unwrap_or_else(|| format!("image {ii}")))
            } else if uri.contains("://") {
                return Err(fail(self, format!("URL '{uri}' is not fetched; only relative file paths and data: URIs")));
            } else {
                let rel = percent_decode(uri);
                let path: PathBuf = self.file.parent().map(|d| d.join(&rel)).unwrap_or_else(|| rel.clone().into());
                match (self.load_file)(&rel) {
                    Ok(d) => (d, path.display().to_string()),
                    Err(e) => return Err(fail(self, format!("cannot read '{}': {e}", path.display()))),
                }
            }
        } else if let Some(vi) = img.get("bufferView").and_then(|v| v.as_u64()) {
            let vi = vi as usize;
            let view = self.root.buffer_views.get(vi).ok_or_else(|| fail(self, format!("bufferView {vi} does not exist")))?;
            let (bi, vo, vl) = (view.buffer.value(), view.byte_offset.map_or(0, |o| o.0), view.byte_length.0);
            let data = self.buffer(bi)?;
            let bytes = usize::try_from(vo)
                .ok()
                .zip(usize::try_from(vl).ok())
                .and_then(|(o, l)| data.get(o..o.checked_add(l)?))
                .map(<[u8]>::to_vec);
            match bytes {
                Some(b) => (b, label.unwrap_or_else(|| format!("image {ii}"))),
                None => return Err(fail(self, format!("bufferView {vi} lies outside buffer {bi}"))),
            }
        } else {
            return Err(fail(self, "neither a uri nor a bufferView".into()));
        };
        let tex = super::Texture::decode(&name, &bytes).map_err(|e| fail(self, format!("'{name}' {e}")))?;
        let t = self.textures.len() as u32;
        self.textures.push(std::sync::Arc::new(tex));
        self.image_texture.insert(ii, t);
        Ok(t)
    }

    /// All triangles of mesh `mi` in its own frame.
    fn mesh_triangles(&mut self, mi: usize) -> Result<MeshTris> {
        let root = self.root;
        let mesh = &root.meshes[mi];
        self.cur_mesh = mi;
        let mut tris = Vec::new();
        for (pi, prim) in mesh.primitives.iter().enumerate() {
            let what = format!("{} primitive {pi}", self.mesh_label(mi));
            let mode = match prim.mode {
                Checked::Valid(m) => m,
                Checked::Invalid => return Err(self.err("meshes", mi, format!("{what}: invalid mode"))),
            };
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                self.warn(self.at("meshes", mi), format!("{what}: mode {mode:?} (points or lines) has no area; skipped"));
                continue;
            }
            let material = match prim.material {
                Some(m) if m.value() >= root.materials.len() => {
                    return Err(self.err(
                        "meshes",
                        mi,
                        format!("{what}: material {} is out of range (there are {})", m.value(), root.materials.len()),
                    ))
                }
                m => m.map(|m| m.value()),
            };
            let Some(pa) = prim.attributes.get(&Checked::Valid(Semantic::Positions)) else {
                return Err(self.err("meshes", mi, format!("{what}: no POSITION attribute")));
            };
            let positions = self.read_positions(pa.value(), &what)?;
            let n = positions.len();
            // Texture coordinates of the sets the material's textures read (all or none).
            let mut sets: Vec<Vec<DVec2>> = Vec::new();
            let wanted = material.map(|m| self.material_tex_coords(m)).unwrap_or_default();
            for set in 0..wanted.iter().max().map_or(0, |m| m + 1) {
                let Some(ta) = prim.attributes.get(&Checked::Valid(Semantic::TexCoords(set as u32))) else {
                    self.warn(
                        self.at("meshes", mi),
                        format!("{what}: its material's texture reads TEXCOORD_{set}, which it lacks; the texture's mean colour is used"),
                    );
                    sets.clear();
                    break;
                };
                let vals = self.read_accessor(ta.value(), Type::Vec2, &what, &format!("TEXCOORD_{set}"))?;
                if vals.len() != 2 * n {
                    return Err(self.err(
                        "accessors",
                        ta.value(),
                        format!("{what}: TEXCOORD_{set} has {} elements, POSITION {n}", vals.len() / 2),
                    ));
                }
                sets.push(vals.chunks_exact(2).map(|c| DVec2::new(c[0], c[1])).collect());
            }
            let idx: Vec<usize> = match prim.indices {
                Some(ia) => {
                    let idx = self.read_indices(ia.value(), &what)?;
                    if let Some(bad) = idx.iter().find(|&&i| i >= n) {
                        return Err(self.err(
                            "accessors",
                            ia.value(),
                            format!("{what}: vertex index {bad} is out of range (the POSITION accessor has {n} elements)"),
                        ));
                    }
                    idx
                }
                None => (0..n).collect(),
            };
            let m = idx.len();
            let mut push = |a: usize, b: usize, c: usize| {
                let uv = sets.iter().map(|s| [s[a], s[b], s[c]]).collect();
                tris.push(Tri { p: [positions[a], positions[b], positions[c]], material, uv })
            };
            match mode {
                Mode::Triangles => {
                    if m % 3 != 0 {
                        self.warnings.push(Warning {
                            loc: Some(self.at("meshes", mi)),
                            msg: format!("{what}: {m} vertices is not a multiple of 3; the last {} are ignored", m % 3),
                        });
                    }
                    for t in idx.chunks_exact(3) {
                        push(t[0], t[1], t[2]);
                    }
                }
                Mode::TriangleStrip => {
                    for i in 0..m.saturating_sub(2) {
                        let (a, b, c) = (idx[i], idx[i + 1 + i % 2], idx[i + 2 - i % 2]);
                        // Repeated indices are the usual way to restart a strip: skip silently.
                        if a != b && b != c && a != c {
                            push(a, b, c);
                        }
                    }
                }
                _ => {
                    for i in 0..m.saturating_sub(2) {
                        push(idx[i + 1], idx[i + 2], idx[0]);
                    }
                }
            }
        }
        Ok(MeshTris { tris })
    }

    fn read_positions(&mut self, ai: usize, what: &str) -> Result<Vec<DVec3>> {
        let root = self.root;
        if let Some(a) = root.accessors.get(ai) {
            // glTF 2.0 §3.7.2.1: POSITION is FLOAT VEC3; KHR_mesh_quantization adds (normalized
            // or not) BYTE, UNSIGNED_BYTE, SHORT and UNSIGNED_SHORT. UNSIGNED_INT never.
            let quantized = root.extensions_used.iter().any(|e| e == "KHR_mesh_quantization")
                || root.extensions_required.iter().any(|e| e == "KHR_mesh_quantization");
            if let Checked::Valid(t) = a.component_type {
                let ok = match t.0 {
                    ComponentType::F32 => !a.normalized,
                    ComponentType::U32 => false,
                    _ => quantized,
                };
                if !ok {
                    let norm = if a.normalized { "normalized " } else { "" };
                    let why = if quantized || t.0 == ComponentType::F32 {
                        "glTF allows FLOAT (not normalized) or, with KHR_mesh_quantization, [UNSIGNED_]BYTE or [UNSIGNED_]SHORT"
                    } else {
                        "glTF requires FLOAT VEC3 (integer positions need the KHR_mesh_quantization extension)"
                    };
                    return Err(self.err(
                        "accessors",
                        ai,
                        format!("{what}: POSITION accessor {ai} has component type {norm}{:?}; {why}", t.0),
                    ));
                }
            }
        }
        let vals = self.read_accessor(ai, Type::Vec3, what, "POSITION")?;
        let label = format!("{what}: POSITION accessor {ai}");
        let mut out = Vec::with_capacity(vals.len() / 3);
        for (k, c) in vals.chunks_exact(3).enumerate() {
            let p = DVec3::new(c[0], c[1], c[2]);
            if !p.is_finite() {
                return Err(self.err("accessors", ai, format!("{label}: position {k} is not finite ({:?})", p.to_array())));
            }
            out.push(p);
        }
        Ok(out)
    }

    fn read_indices(&mut self, ai: usize, what: &str) -> Result<Vec<usize>> {
        let root = self.root;
        if let Some(a) = root.accessors.get(ai) {
            if a.normalized {
                return Err(self.err("accessors", ai, format!("{what}: index accessor {ai} is normalized (indices must not be)")));
            }
            if let Checked::Valid(t) = a.component_type {
                if !matches!(t.0, ComponentType::U8 | ComponentType::U16 | ComponentType::U32) {
                    return Err(self.err(
                        "accessors",
                        ai,
                        format!("{what}: index accessor {ai} has component type {:?} (must be an unsigned integer)", t.0),
                    ));
                }
            }
        }
        let vals = self.read_accessor(ai, Type::Scalar, what, "indices")?;
        Ok(vals.into_iter().map(|v| v as usize).collect())
    }

    /// The values of accessor `ai` (count × components), converted to f64 (normalized
    /// integers mapped to [0,1] or [−1,1] as the specification says), sparse values applied.
    fn read_accessor(&mut self, ai: usize, ty: Type, what: &str, role: &str) -> Result<Vec<f64>> {
        let root = self.root;
        let Some(acc) = root.accessors.get(ai) else {
            return Err(Error::input(
                self.at("meshes", self.cur_mesh),
                format!("{what}: {role} accessor {ai} is out of range (there are {})", root.accessors.len()),
            ));
        };
        let e = |s: &Self, msg: String| s.err("accessors", ai, format!("{what}: {role} accessor {ai}: {msg}"));
        let t = match acc.type_ {
            Checked::Valid(t) => t,
            Checked::Invalid => return Err(e(self, "invalid type".into())),
        };
        if t != ty {
            return Err(e(self, format!("type is {t:?}, expected {ty:?}")));
        }
        let comp = match acc.component_type {
            Checked::Valid(c) => c.0,
            Checked::Invalid => return Err(e(self, "invalid componentType".into())),
        };
        let ncomp = ty.multiplicity();
        let count = usize::try_from(acc.count.0).map_err(|_| e(self, "count is too large".into()))?;
        let mut out: Vec<f64> = match acc.buffer_view {
            Some(v) => {
                let stride_default = comp_size(comp) * ncomp;
                let offset = acc.byte_offset.map(|o| o.0).unwrap_or(0);
                let offset = usize::try_from(offset).map_err(|_| e(self, "byteOffset is too large".into()))?;
                self.read_view(v.value(), offset, count, comp, ncomp, acc.normalized, Some(stride_default))
                    .map_err(|m| m.place(|m| e(self, m)))?
            }
            None => {
                if count > MAX_ZERO_ACCESSOR {
                    return Err(e(self, format!("count {count} is too large for an accessor without a bufferView")));
                }
                vec![0.0; count * ncomp]
            }
        };
        if let Some(sp) = &acc.sparse {
            let n = usize::try_from(sp.count.0).map_err(|_| e(self, "sparse count is too large".into()))?;
            let icomp = match sp.indices.component_type {
                Checked::Valid(c) => c.0,
                Checked::Invalid => return Err(e(self, "invalid sparse index componentType".into())),
            };
            let ioff = usize::try_from(sp.indices.byte_offset.0).map_err(|_| e(self, "sparse byteOffset is too large".into()))?;
            let idx = self
                .read_view(sp.indices.buffer_view.value(), ioff, n, icomp, 1, false, None)
                .map_err(|m| m.place(|m| e(self, format!("sparse indices: {m}"))))?;
            let voff = usize::try_from(sp.values.byte_offset.0).map_err(|_| e(self, "sparse byteOffset is too large".into()))?;
            let vals = self
                .read_view(sp.values.buffer_view.value(), voff, n, comp, ncomp, acc.normalized, None)
                .map_err(|m| m.place(|m| e(self, format!("sparse values: {m}"))))?;
            for (k, &i) in idx.iter().enumerate() {
                let i = i as usize;
                if i >= count {
                    return Err(e(self, format!("sparse index {i} is out of range (count {count})")));
                }
                out[i * ncomp..(i + 1) * ncomp].copy_from_slice(&vals[k * ncomp..(k + 1) * ncomp]);
            }
        }
        Ok(out)
    }

    /// Reads `count` elements of `ncomp` components from buffer view `vi`, starting
    /// `offset` bytes into it. `stride`: Some(default) honours the view's byteStride (vertex
    /// attributes); None reads tightly packed (indices, sparse data).
    #[allow(clippy::too_many_arguments)]
    fn read_view(
        &mut self,
        vi: usize,
        offset: usize,
        count: usize,
        comp: ComponentType,
        ncomp: usize,
        normalized: bool,
        stride: Option<usize>,
    ) -> std::result::Result<Vec<f64>, ViewError> {
        let root = self.root;
        let view = root.buffer_views.get(vi).ok_or_else(|| format!("bufferView {vi} is out of range"))?;
        let elem = comp_size(comp) * ncomp;
        let stride = match (stride, view.byte_stride) {
            (Some(_), Some(s)) if s.0 > 0 => s.0,
            (Some(d), _) => d,
            (None, _) => elem,
        };
        if stride < elem {
            return Err(format!("bufferView {vi} byteStride {stride} is smaller than an element ({elem} bytes)").into());
        }
        let bi = view.buffer.value();
        let vo = usize::try_from(view.byte_offset.map(|o| o.0).unwrap_or(0)).map_err(|_| "byteOffset too large")?;
        let vl = usize::try_from(view.byte_length.0).map_err(|_| "byteLength too large")?;
        let data = self.buffer(bi).map_err(ViewError::Placed)?;
        let view_data = vo
            .checked_add(vl)
            .and_then(|end| data.get(vo..end))
            .ok_or_else(|| format!("bufferView {vi} (bytes {vo}..{vo}+{vl}) lies outside buffer {bi} ({} bytes)", data.len()))?;
        if count == 0 {
            return Ok(Vec::new());
        }
        let need = (count - 1).checked_mul(stride).and_then(|x| x.checked_add(elem)).and_then(|x| x.checked_add(offset));
        match need {
            Some(n) if n <= view_data.len() => {}
            _ => {
                return Err(format!(
                    "{count} elements of {elem} bytes (stride {stride}) from byte {offset} do not fit in bufferView {vi} ({} bytes)",
                    view_data.len()
                )
                .into())
            }
        }
        let cs = comp_size(comp);
        let mut out = Vec::with_capacity(count * ncomp);
        for k in 0..count {
            let base = offset + k * stride;
            for c in 0..ncomp {
                let s = &view_data[base + c * cs..base + (c + 1) * cs];
                out.push(component(s, comp, normalized));
            }
        }
        Ok(out)
    }

    /// The bytes of buffer `bi`, loaded on first use; errors are placed at the buffer.
    fn buffer(&mut self, bi: usize) -> Result<&[u8]> {
        let root = self.root;
        let Some(b) = root.buffers.get(bi) else {
            return Err(Error::input(
                Location::file(self.file),
                format!("buffer {bi} is out of range (there are {})", root.buffers.len()),
            ));
        };
        if self.buffers[bi].is_none() {
            let fail = |s: &Self, msg: String| s.err("buffers", bi, format!("buffer {bi}: {msg}"));
            let data = match &b.uri {
                None => match (bi, self.blob) {
                    (0, Some(blob)) => blob.to_vec(),
                    _ => return Err(fail(self, "no uri, and the file has no GLB binary chunk".into())),
                },
                Some(uri) if uri.starts_with("data:") => {
                    let Some(pos) = uri.find(";base64,") else {
                        return Err(fail(self, "only base64 data: URIs are supported".into()));
                    };
                    let engine = base64::engine::GeneralPurpose::new(
                        &base64::alphabet::STANDARD,
                        base64::engine::GeneralPurposeConfig::new()
                            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
                    );
                    engine
                        .decode(uri[pos + 8..].trim_end())
                        .map_err(|err| fail(self, format!("invalid base64 data: {err}")))?
                }
                Some(uri) if uri.contains("://") => {
                    return Err(fail(self, format!("URL '{uri}' is not fetched; only relative file paths and data: URIs")))
                }
                Some(uri) => {
                    let rel = percent_decode(uri);
                    match (self.load_file)(&rel) {
                        Ok(d) => d,
                        Err(err) => {
                            let p: PathBuf = self.file.parent().map(|d| d.join(&rel)).unwrap_or_else(|| rel.clone().into());
                            return Err(fail(self, format!("cannot read '{}': {err}", p.display())));
                        }
                    }
                }
            };
            let want = b.byte_length.0;
            if (data.len() as u64) < want {
                return Err(fail(self, format!("{} bytes, but byteLength says {want}", data.len())));
            }
            self.buffers[bi] = Some(data);
        }
        Ok(self.buffers[bi].as_deref().unwrap_or(&[]))
    }
}

/// A failed buffer-view read: a message for the caller to place at its accessor, or an
/// error already placed (at the buffer).
enum ViewError {
    Msg(String),
    Placed(Error),
}

impl ViewError {
    fn place(self, at: impl FnOnce(String) -> Error) -> Error {
        match self {
            ViewError::Msg(m) => at(m),
            ViewError::Placed(e) => e,
        }
    }
}

impl From<String> for ViewError {
    fn from(m: String) -> Self {
        ViewError::Msg(m)
    }
}

impl From<&str> for ViewError {
    fn from(m: &str) -> Self {
        ViewError::Msg(m.into())
    }
}

/// The texture-coordinate set a `textureInfo` reads (`KHR_texture_transform` may override).
fn tex_coord_of(info: &serde_json::Value) -> u32 {
    let own = info.get("texCoord").and_then(|v| v.as_u64()).unwrap_or(0);
    let over = info.get("extensions").and_then(|x| x.get("KHR_texture_transform")).and_then(|t| t.get("texCoord")).and_then(|v| v.as_u64());
    over.unwrap_or(own).min(7) as u32
}

fn comp_size(c: ComponentType) -> usize {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// One little-endian component (`s` has exactly its size).
fn component(s: &[u8], c: ComponentType, normalized: bool) -> f64 {
    let four = |s: &[u8]| [s[0], s[1], s[2], s[3]];
    match c {
        ComponentType::F32 => f64::from(f32::from_le_bytes(four(s))),
        ComponentType::I8 => {
            let v = f64::from(s[0] as i8);
            if normalized { (v / 127.0).max(-1.0) } else { v }
        }
        ComponentType::U8 => {
            let v = f64::from(s[0]);
            if normalized { v / 255.0 } else { v }
        }
        ComponentType::I16 => {
            let v = f64::from(i16::from_le_bytes([s[0], s[1]]));
            if normalized { (v / 32767.0).max(-1.0) } else { v }
        }
        ComponentType::U16 => {
            let v = f64::from(u16::from_le_bytes([s[0], s[1]]));
            if normalized { v / 65535.0 } else { v }
        }
        ComponentType::U32 => {
            let v = f64::from(u32::from_le_bytes(four(s)));
            if normalized { v / 4_294_967_295.0 } else { v }
        }
    }
}

/// `%20` → space etc. (glTF URIs are percent-encoded); malformed escapes are kept as is.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = |c: u8| (c as char).to_digit(16);
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_lines_finds_array_elements() {
        let text = "{\n \"asset\": {\"version\": \"2.0\"},\n \"materials\": [\n  {\"name\": \"a\"},\n  {\"name\": \"b,]\"}\n ],\n \"x\": [1, 2]\n}";
        let l = JsonLines::new(text);
        assert_eq!(l.line("materials", 0), Some(4));
        assert_eq!(l.line("materials", 1), Some(5));
        assert_eq!(l.line("materials", 2), None);
        assert_eq!(l.line("x", 1), Some(7));
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("%zz"), "%zz");
    }

    #[test]
    fn glb_splitting_rejects_truncation() {
        assert!(split_glb(b"glTF").is_err());
        let mut v = b"glTF".to_vec();
        v.extend(2u32.to_le_bytes());
        v.extend(100u32.to_le_bytes());
        assert!(split_glb(&v).unwrap_err().contains("truncated"));
    }
}
