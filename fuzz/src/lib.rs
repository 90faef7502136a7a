//! Helpers shared by the fuzz targets: splitting an input into parts, a per-process
//! scratch folder, and the common "go deeper" step run on every scene that loads.

use std::path::PathBuf;
use std::sync::OnceLock;

use radiosity::mesh;
use radiosity::scene::{Scene, SceneDesc};

/// Separator between the parts of a multi-part input (OBJ | MTL, glTF JSON | external
/// buffer, TOML | mesh file): the first NUL byte. None of the text formats uses NUL.
pub const SEP: u8 = 0;

/// Most elements the uniform mesher may produce in one run (larger scenes are skipped).
pub const MAX_ELEMENTS: u64 = 20_000;

/// Splits at the first [`SEP`]: (before, Some(after)) or (all, None).
pub fn split(data: &[u8]) -> (&[u8], Option<&[u8]>) {
    match data.iter().position(|&b| b == SEP) {
        Some(i) => (&data[..i], Some(&data[i + 1..])),
        None => (data, None),
    }
}

/// Text the way the loaders read files: UTF-8, lossily.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A scratch folder for this process (created once, reused by every run).
pub fn scratch_dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("radiosity-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("create scratch folder");
        d
    })
}

/// Validates a loaded description and, for small scenes, meshes it uniformly. `knob`
/// (a byte of the input) picks the element size as a fraction of the scene's diagonal,
/// so the fuzzer also explores the mesher's parameters. Errors are fine; panics are bugs.
pub fn exercise(desc: SceneDesc, knob: u8) {
    let Ok(scene) = Scene::from_desc(desc) else { return };
    let _ = scene.bounds();
    let _ = scene.total_area();
    let diag = scene.diagonal();
    if !(diag.is_finite() && diag > 0.0) {
        return;
    }
    let size = diag / f64::from(1 + knob % 32);
    if mesh::count_uniform(&scene, size) > MAX_ELEMENTS {
        return;
    }
    let _ = mesh::mesh_uniform(&scene, size);
}

/// The last byte of the input (0 when empty): the mesher knob.
pub fn knob(data: &[u8]) -> u8 {
    data.last().copied().unwrap_or(0)
}
