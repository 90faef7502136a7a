//! Camera JSON and views JSON: the same text goes to both parsers.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::Camera;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(cam) = Camera::from_json_str(text, Path::new("camera.json")) {
        let _ = cam.validate();
    }
    if let Ok(views) = Camera::parse_views(text, Path::new("views.json")) {
        for (_, cam) in views {
            let _ = cam.validate();
        }
    }
});
