//! View3D `.vs3` text.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::vs3::parse_vs3;
use radiosity_fuzz::{exercise, knob, text};

fuzz_target!(|data: &[u8]| {
    if let Ok((desc, _control)) = parse_vs3(&text(data), Path::new("f.vs3")) {
        exercise(desc, knob(data));
    }
});
