//! glTF 2.0 reader (placeholder; see issue 2).

use std::path::Path;

use super::SceneDesc;
use crate::{Error, Location, Result};

/// Reads a `.gltf` or `.glb` file.
pub fn load_gltf(path: &Path) -> Result<SceneDesc> {
    Err(Error::input(Location::file(path), "glTF reading is not available yet"))
}
