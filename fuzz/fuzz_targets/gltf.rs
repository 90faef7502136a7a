//! glTF: a GLB (input starts with `glTF`: the whole input is the file) or glTF JSON with
//! an optional external buffer, `json-bytes [NUL buffer-bytes]`: every external URI reads
//! the buffer part (or fails like a missing file when there is none).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::gltf::parse_gltf;
use radiosity_fuzz::{exercise, knob, split};

fuzz_target!(|data: &[u8]| {
    let res = if data.starts_with(b"glTF") {
        parse_gltf(data, Path::new("f.glb"), |_| Err(std::io::ErrorKind::NotFound.into()))
    } else {
        let (json, buf) = split(data);
        parse_gltf(json, Path::new("f.gltf"), |_| match buf {
            Some(b) => Ok(b.to_vec()),
            None => Err(std::io::ErrorKind::NotFound.into()),
        })
    };
    if let Ok(desc) = res {
        exercise(desc, knob(data));
    }
});
