//! View factors between the faces of a mesh held in memory, with occlusion — the same
//! library calls the Python package makes (`radiosity.view_factors`).
//!
//!     cargo run --release -p radiosity --example view_factors
//!
//! Two unit squares facing each other at distance 1, and a smaller square between them
//! that only blocks (an obstruction: no row of its own).

use radiosity::scene::arrays::{scene_from_arrays, Arrays};
use radiosity::scene::Scene;
use radiosity::view_factors::{self, Per, Settings};
use radiosity::NoProgress;

fn main() -> radiosity::Result<()> {
    let vertices = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0], // floor, facing up
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [0.0, 1.0, 1.0], // ceiling, facing down
        [0.25, 0.25, 0.5],
        [0.75, 0.25, 0.5],
        [0.75, 0.75, 0.5],
        [0.25, 0.75, 0.5], // a blocker in between
    ];
    let faces = vec![vec![0, 1, 2, 3], vec![7, 6, 5, 4], vec![8, 9, 10, 11]];
    let arrays = Arrays { vertices: &vertices, faces: &faces, labels: &[], obstruction: &[false, false, true] };
    let (desc, surfaces) = scene_from_arrays(&arrays)?;
    let scene = Scene::from_desc(desc)?;
    // Error-controlled integration with occlusion by rays (the default method).
    let vf = view_factors::compute(scene, &Settings { per: Per::Object, ..Default::default() }, &NoProgress)?;
    println!("surfaces (face labels): {surfaces:?}, areas {:?}", vf.areas);
    for (i, name) in vf.names.iter().enumerate() {
        println!("F[{name}][·] = {:?}", vf.matrix.row(i));
    }
    println!(
        "unblocked the factor would be 0.199825; reciprocity error {:.1e}",
        vf.diagnostics.reciprocity_max_rel.unwrap_or(0.0)
    );
    Ok(())
}
