//! Cameras as described in scene files and `camera.json`.
//!
//! Convention (PRODUCT.md): a pinhole at `position` looking at `look_at`, `up` roughly up,
//! `vfov_deg` the full vertical field of view in degrees; image right = forward × up, so a
//! right-handed scene seen with +Y up and looking along +Z has +X on the left (the Cornell
//! box's red wall). Pixel (0,0) is top-left; pixel centres at +0.5.

use std::path::Path;

use glam::DVec3;
use serde::Deserialize;

use crate::{Error, Location, Result};

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub position: DVec3,
    /// Point looked at.
    pub look_at: DVec3,
    /// Up direction (need not be orthogonal to the view direction).
    pub up: DVec3,
    /// Full vertical field of view in degrees.
    pub vfov_deg: f64,
}

/// The JSON form (`../shared/scenes/cornell-box/camera.json`). Keys other than these four
/// are descriptive (`aspect`, `units`, `model`, `source`, `width`, `height`, ...) and
/// ignored.
#[derive(Deserialize)]
struct CameraJson {
    position: [f64; 3],
    look_at: [f64; 3],
    up: [f64; 3],
    vfov_deg: f64,
}

impl Camera {
    /// Checks the camera is usable: finite, position ≠ look_at, up not parallel to the view,
    /// 0 < fov < 180.
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.check().map_err(|(_, m)| m)
    }

    /// [`Camera::validate`], also naming the field at fault (for error locations).
    fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        let max = super::MAX_COORDINATE;
        for (field, v) in [("position", self.position), ("look_at", self.look_at), ("up", self.up)] {
            if !v.is_finite() {
                return Err((field, format!("camera {field} must be finite numbers, got {:?}", v.to_array())));
            }
            if v.abs().max_element() > max {
                return Err((field, format!("camera {field} {:?} has a coordinate of magnitude above {max:e}", v.to_array())));
            }
        }
        if !self.vfov_deg.is_finite() {
            return Err(("vfov_deg", "camera values must be finite numbers".into()));
        }
        let fwd = self.look_at - self.position;
        let scale = self.position.abs().max_element().max(self.look_at.abs().max_element());
        if fwd.length() <= 1e-12 * scale || fwd.length() == 0.0 {
            return Err(("look_at", "camera position and look_at coincide".into()));
        }
        if !(self.up.length() > 0.0) || fwd.normalize().cross(self.up.normalize()).length() < 1e-9 {
            return Err(("up", "camera up is parallel to the view direction (or zero)".into()));
        }
        if !(self.vfov_deg > 0.0 && self.vfov_deg < 180.0) {
            return Err(("vfov_deg", format!("vfov_deg must be between 0 and 180 degrees, got {}", self.vfov_deg)));
        }
        Ok(())
    }

    /// Parses the JSON form; `file` names the source in errors (with the line of the
    /// offending key where one can be found).
    pub fn from_json_str(text: &str, file: &Path) -> Result<Camera> {
        let j: CameraJson = serde_json::from_str(text).map_err(|e| {
            // serde_json's message ends in " at line L column C"; the location says it.
            let full = e.to_string();
            let msg = full.rfind(" at line ").map_or(full.as_str(), |i| &full[..i]).to_string();
            Error::Input {
                loc: Location { file: file.into(), line: Some(e.line().max(1)), column: Some(e.column().max(1)) },
                msg: format!("invalid camera JSON: {msg}"),
            }
        })?;
        let cam = Camera {
            position: DVec3::from_array(j.position),
            look_at: DVec3::from_array(j.look_at),
            up: DVec3::from_array(j.up),
            vfov_deg: j.vfov_deg,
        };
        cam.check().map_err(|(field, m)| {
            let key = format!("\"{field}\"");
            let loc = match text.find(&key) {
                Some(off) => Location::line(file, text[..off].matches('\n').count() + 1),
                None => Location::file(file),
            };
            Error::input(loc, m)
        })?;
        Ok(cam)
    }

    /// Reads a camera JSON file.
    pub fn load_json(path: &Path) -> Result<Camera> {
        let text = super::read_input_text(path)?;
        Camera::from_json_str(&text, path)
    }

    /// Reads a list of views: a JSON array of cameras (the form above, each optionally with
    /// a `"name"`), or an object `{"views": [...]}`. Unnamed views are called `view<k>`.
    pub fn load_views(path: &Path) -> Result<Vec<(String, Camera)>> {
        let text = super::read_input_text(path)?;
        Camera::parse_views(&text, path)
    }

    /// Parses the text of a views file (see [`Camera::load_views`]); `path` names the
    /// source in errors.
    pub fn parse_views(text: &str, path: &Path) -> Result<Vec<(String, Camera)>> {
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| Error::Input {
            loc: Location { file: path.into(), line: Some(e.line()), column: Some(e.column()) },
            msg: format!("invalid views JSON: {e}"),
        })?;
        let list = match &v {
            serde_json::Value::Array(a) => a.clone(),
            serde_json::Value::Object(o) => match o.get("views") {
                Some(serde_json::Value::Array(a)) => a.clone(),
                _ => return Err(Error::input(Location::file(path), "expected a JSON array of cameras or {\"views\": [...]}")),
            },
            _ => return Err(Error::input(Location::file(path), "expected a JSON array of cameras or {\"views\": [...]}")),
        };
        if list.is_empty() {
            return Err(Error::input(Location::file(path), "the view list is empty"));
        }
        let mut out = Vec::with_capacity(list.len());
        for (k, item) in list.iter().enumerate() {
            let name = item.get("name").and_then(|n| n.as_str()).map(str::to_string).unwrap_or_else(|| format!("view{k}"));
            if !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.') {
                return Err(Error::input(Location::file(path), format!("view {k}: name '{name}' may use only letters, digits, '_', '-' and '.'")));
            }
            let j: CameraJson = serde_json::from_value(item.clone())
                .map_err(|e| Error::input(Location::file(path), format!("view {k} ('{name}'): {e}")))?;
            let cam = Camera {
                position: DVec3::from_array(j.position),
                look_at: DVec3::from_array(j.look_at),
                up: DVec3::from_array(j.up),
                vfov_deg: j.vfov_deg,
            };
            cam.validate().map_err(|m| Error::input(Location::file(path), format!("view {k} ('{name}'): {m}")))?;
            out.push((name, cam));
        }
        Ok(out)
    }

    /// A camera that frames a bounding box: looks at its centre from outside, along the
    /// direction that sees the largest face, with a 45° field of view.
    pub fn framing(lo: DVec3, hi: DVec3) -> Camera {
        let center = 0.5 * (lo + hi);
        let ext = (hi - lo).max(DVec3::splat(1e-9));
        let radius = 0.5 * ext.length();
        let vfov_deg: f64 = 45.0;
        // Up: +Z for scenes that are flat in Z (architecture with z up), else +Y.
        let up = if ext.z < ext.y * 0.9 && ext.z < ext.x * 0.9 { DVec3::Z } else { DVec3::Y };
        // Look along +Z for y-up scenes (the Cornell convention) and along +Y for z-up
        // scenes, from the negative side, slightly from above.
        let horiz = if up == DVec3::Z { DVec3::Y } else { DVec3::Z };
        let dir = (horiz - 0.25 * up).normalize();
        let dist = radius / (0.5 * vfov_deg.to_radians()).tan() * 1.05;
        Camera { position: center - dir * dist, look_at: center, up, vfov_deg }
    }
}
