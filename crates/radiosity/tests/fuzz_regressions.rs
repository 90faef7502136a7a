//! Inputs found by the fuzz targets in `fuzz/` (scripts/fuzz.sh, docs/RELIABILITY.md)
//! that once panicked, hung or ran out of memory. Each must now give a clear error (or a
//! correct result). The bytes are the minimised crash artefacts, inline.

use std::path::Path;

use radiosity::scene::vs3::parse_vs3;

/// Text the way the loaders read a file (lossy UTF-8).
fn lossy(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// fuzz target `vs3`: a `T` line after a leading ',' (a View3D word separator) with a
/// non-ASCII title sliced the line at the wrong byte: "byte index 4 is not a char boundary".
#[test]
fn vs3_title_after_leading_comma() {
    let e = parse_vs3(&lossy(b",T\xa0 ,\xa0 "), Path::new("f.vs3")).unwrap_err().to_string();
    assert!(e.starts_with("f.vs3") && e.contains("no surfaces"), "{e}");
    // And the title itself is the rest of the line after the first word.
    let text = ",T\u{e9}t\u{e9}  Two plates \nF 3\nV 1 0 0 0\nV 2 1 0 0\nV 3 1 1 0\nV 4 0 1 0\n\
                S 1 1 2 3 4 0 0 0.5 a\nE\n";
    let (_, ctrl) = parse_vs3(text, Path::new("f.vs3")).unwrap();
    assert_eq!(ctrl.title, "Two plates");
}
