//! OBJ text with an optional MTL: `obj-bytes [NUL mtl-bytes]`. Every `mtllib` reads the
//! MTL part (or fails like a missing file when there is none).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use radiosity::scene::obj::{parse_mtl, parse_obj};
use radiosity::{Error, Location};
use radiosity_fuzz::{exercise, knob, split, text};

fuzz_target!(|data: &[u8]| {
    let (obj, mtl) = split(data);
    let obj = text(obj);
    let mtl = mtl.map(text);
    if let Some(m) = &mtl {
        let _ = parse_mtl(m, Path::new("f.mtl"));
    }
    let res = parse_obj(&obj, Path::new("f.obj"), |name, loc: &Location| match &mtl {
        Some(m) => parse_mtl(m, Path::new(name)),
        None => Err(Error::input(loc.clone(), format!("cannot read material library '{name}'"))),
    });
    if let Ok(desc) = res {
        exercise(desc, knob(data));
    }
});
