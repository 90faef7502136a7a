//! TOML scene files (placeholder; see issue 2).

use std::path::Path;

use super::SceneDesc;
use crate::{Error, Location, Result};

/// Reads a TOML scene file.
pub fn load_toml(path: &Path) -> Result<SceneDesc> {
    Err(Error::input(Location::file(path), "TOML scene files are not available yet"))
}
