//! Grey-body radiative exchange in a closed cube: a hot floor, a cold ceiling and
//! re-radiating walls — the library calls behind `radiosity thermal` and the Python
//! package's `radiosity.exchange`.
//!
//!     cargo run --release -p radiosity --example thermal_exchange

use radiosity::scene::arrays::{scene_from_arrays, Arrays};
use radiosity::scene::{Boundary, Scene, ThermalDesc};
use radiosity::thermal::{self, Settings};
use radiosity::{NoProgress, Rgb};

fn main() -> radiosity::Result<()> {
    let vertices: Vec<[f64; 3]> =
        (0..8).map(|k| [(k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64]).collect();
    // Faces wound inward (counter-clockwise seen from inside the cube).
    let faces = vec![
        vec![1, 3, 2, 0], // floor z = 0
        vec![6, 7, 5, 4], // ceiling z = 1
        vec![4, 5, 1, 0], // walls
        vec![3, 7, 6, 2],
        vec![2, 6, 4, 0],
        vec![5, 7, 3, 1],
    ];
    // Surface labels: the four walls form one surface.
    let labels = [0, 1, 2, 2, 2, 2];
    let (mut desc, _) =
        scene_from_arrays(&Arrays { vertices: &vertices, faces: &faces, labels: &labels, obstruction: &[] })?;
    let conditions =
        [(0.8, Boundary::Temperature(600.0)), (0.5, Boundary::Temperature(300.0)), (0.3, Boundary::Adiabatic)];
    for (m, (eps, boundary)) in desc.materials.iter_mut().zip(conditions) {
        m.reflectance = Rgb::splat(1.0 - eps);
        m.thermal = Some(ThermalDesc { emissivity: Some(eps), boundary: Some(boundary), ..Default::default() });
    }
    let mut settings = Settings::default();
    settings.view_factors.mesh_size = Some(0.1);
    settings.view_factors.enclosure = true; // closed: reciprocity and closure enforced
    let th = thermal::solve(Scene::from_desc(desc)?, &settings, &NoProgress)?;
    for s in &th.surfaces {
        println!(
            "{:>4}: ε {:.2}  T {:7.2} K  q {:10.3} W/m²  Q {:10.3} W",
            s.name, s.emissivity, s.temperature, s.heat_flux, s.heat
        );
    }
    println!("balance ΣQ = {:.2e} W of Σ|Q| = {:.1} W ({} elements)", th.balance, th.total, th.elements);
    Ok(())
}
