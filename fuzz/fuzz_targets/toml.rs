//! TOML scene files: `toml-bytes [NUL mesh-bytes]`. The mesh part is written to `m.obj`
//! and `m.gltf` in a per-process scratch folder (empty files when there is none), so the
//! TOML can use `mesh = "m.obj"`, `"m.gltf"` or `"builtin:NAME"`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radiosity::scene::toml_file::parse_toml;
use radiosity_fuzz::{exercise, knob, scratch_dir, split, text};

fuzz_target!(|data: &[u8]| {
    let (toml, mesh) = split(data);
    let dir = scratch_dir();
    let mesh = mesh.unwrap_or(b"");
    std::fs::write(dir.join("m.obj"), mesh).expect("write m.obj");
    std::fs::write(dir.join("m.gltf"), mesh).expect("write m.gltf");
    if let Ok(desc) = parse_toml(&text(toml), &dir.join("f.toml"), dir) {
        exercise(desc, knob(data));
    }
});
