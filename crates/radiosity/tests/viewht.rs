//! View3D/ViewHT compatibility of the thermal solver:
//!
//! - ViewHT's own test case (Walton, NIST): its emittance-weighted factors and
//!   temperatures give the fluxes ViewHT printed;
//! - Hottel's total exchange factors `ℱ = εB` of two concentric spheres are the
//!   two-surface closed form; rows sum to ε; `Aℱ` is symmetric;
//! - the View3D examples (`ParallelPlanes.vs3`, `box345.vs3`) with temperatures from a
//!   ViewHT temperature file balance to 1e-9 (ΣQ − Q_env), and the open parallel plates
//!   match the network of two grey plates and a black environment;
//! - one answer three ways: the thermal solve, and ViewHT's table on the emittance-weighted
//!   factors of the same view factors, agree to rounding.

use std::path::{Path, PathBuf};

use radiosity::scene::{vs3, Scene};
use radiosity::thermal::viewht::{heat_table, load_temperatures, load_view_factor_file, ViewFactorFile};
use radiosity::thermal::{
    set_temperatures, solve, surface_objects, total_exchange_factors, Settings, STEFAN_BOLTZMANN as SIGMA,
};
use radiosity::view_factors::{self, Per, Settings as VfSettings};
use radiosity::NoProgress;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

#[test]
fn viewht_reproduces_waltons_test_case() {
    let vf = load_view_factor_file(&data("viewht-viewfactors.txt")).unwrap();
    assert!(vf.emittances && vf.enclosure && vf.len() == 8);
    let t: Vec<f64> =
        load_temperatures(&data("viewht-temperatures.txt"), 8).unwrap().into_iter().map(Option::unwrap).collect();
    assert_eq!(t[2], 283.15);
    let table = heat_table(&vf, &t, 0.0).unwrap();
    // ViewHT's output-expected.txt (q absorbed, W/m², σ = 5.6697e-8): our q leaves, CODATA σ.
    let viewht = [-1.706e1, -1.483e1, 4.748e1, -3.343e-1, -4.038e-1, -1.769, -6.776, -6.776];
    for (k, (r, v)) in table.rows.iter().zip(viewht).enumerate() {
        let ours = -r.heat_flux * 5.6697e-8 / SIGMA;
        assert!((ours - v).abs() <= 6e-4 * v.abs(), "surface {}: {ours} vs ViewHT {v}", k + 1);
    }
    assert!(table.balance.abs() <= 1e-9 * table.total, "balance {} of {}", table.balance, table.total);
}

#[test]
fn total_exchange_factors_of_concentric_spheres_are_the_closed_form() {
    let (a1, a2, e1, e2) = (1.0, 4.0, 0.3, 0.6);
    let f = [0.0, 1.0, a1 / a2, 1.0 - a1 / a2];
    let x = total_exchange_factors(&f, &[e1, e2]).unwrap();
    let exact = 1.0 / (1.0 / e1 + (a1 / a2) * (1.0 / e2 - 1.0));
    assert!((x[1] - exact).abs() < 1e-14, "{} vs {exact}", x[1]);
    assert!((x[0] + x[1] - e1).abs() < 1e-14 && (x[2] + x[3] - e2).abs() < 1e-14, "rows {x:?}");
    assert!((a1 * x[1] - a2 * x[2]).abs() < 1e-14);
    assert!(total_exchange_factors(&f, &[0.0, 0.5]).unwrap_err().to_string().contains("emissivity 0 of surface 1"));
}

fn settings(mesh_size: Option<f64>, enclosure: bool) -> Settings {
    let mut vf = VfSettings { per: Per::Element, mesh_size, enclosure, ..Default::default() };
    vf.form_factors.method = radiosity::form_factor::Method::PointSampled;
    Settings { view_factors: vf, environment: 0.0, band_edges: None }
}

fn temperature_file(name: &str, text: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("radiosity-viewht-{}-{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn parallel_planes_with_temperatures_match_the_grey_network_and_balance() {
    let (mut desc, _) = vs3::read_vs3(&data("ParallelPlanes.vs3")).unwrap();
    let tf = temperature_file("pp.txt", "1 1 400 ! bottom\n2 2 300\n0 0\n");
    let t = load_temperatures(&tf, surface_objects(&desc).len()).unwrap();
    let _ = std::fs::remove_file(&tf);
    set_temperatures(&mut desc, &t).unwrap();
    // Open geometry: the balance closes as far as the factors are reciprocal (exact here).
    let mut s = settings(None, false);
    s.view_factors.form_factors.method = radiosity::form_factor::Method::Analytic;
    let th = solve(Scene::from_desc(desc).unwrap(), &s, &NoProgress).unwrap();
    assert!(th.balance.abs() <= 1e-9 * th.total, "balance {} of {}", th.balance, th.total);
    // Two grey plates (ε = 0.9) facing each other, F = 0.199825, the rest to black space at 0 K.
    let (f, e) = (0.199824895698, 0.9);
    let (b1, b2) = (e * SIGMA * 400f64.powi(4), e * SIGMA * 300f64.powi(4));
    let r = (1.0 - e) * f;
    let j1 = (b1 + r * b2) / (1.0 - r * r);
    let j2 = b2 + r * j1;
    let q1 = j1 - f * j2;
    let got = th.surfaces[0].heat;
    println!("parallel planes: Q1 = {got} W, network {q1} W, {} elements", th.elements);
    assert!((got - q1).abs() <= 5e-3 * q1, "Q1 {got} vs {q1}");
}

#[test]
fn box345_with_a_viewht_temperature_file_balances() {
    let (mut desc, ctrl) = vs3::read_vs3(&data("box345.vs3")).unwrap();
    assert!(ctrl.enclosure);
    let n = surface_objects(&desc).len();
    // ViewHT style: a range past the last surface stops there; later lines win.
    let tf = temperature_file("box.txt", "1 999 300 ! every surface\n1 10 350\n0 0\n");
    let t = load_temperatures(&tf, n).unwrap();
    let _ = std::fs::remove_file(&tf);
    assert!(t.iter().all(Option::is_some) && t[9] == Some(350.0) && t[10] == Some(300.0));
    set_temperatures(&mut desc, &t).unwrap();
    let th = solve(Scene::from_desc(desc).unwrap(), &settings(Some(1.0), true), &NoProgress).unwrap();
    assert_eq!(th.surfaces.len(), n);
    assert!(th.balance.abs() <= 1e-9 * th.total, "balance {} of {}", th.balance, th.total);
    // Hot surfaces lose heat, the others gain.
    assert!(th.surfaces[..10].iter().all(|s| s.heat > 0.0) && th.surfaces[10..].iter().all(|s| s.heat <= 1e-9));
}

#[test]
fn thermal_solve_and_viewht_on_emittance_weighted_factors_agree() {
    // One element per surface: both paths solve the same system.
    let (mut desc, _) = vs3::read_vs3(&data("ParallelPlanes.vs3")).unwrap();
    let vs = VfSettings { per: Per::Object, mesh_size: Some(0.0), enclosure: false, ..Default::default() };
    let scene = Scene::from_desc(desc.clone()).unwrap();
    let vf = view_factors::compute(scene, &vs, &NoProgress).unwrap();
    let f = vf.matrix.as_slice();
    let eps = vec![0.9, 0.9];
    let file = ViewFactorFile {
        program: "test".into(),
        enclosure: false,
        emittances: true,
        areas: vf.areas.clone(),
        factors: total_exchange_factors(f, &eps).unwrap(),
        emissivity: eps,
    };
    let table = heat_table(&file, &[400.0, 300.0], 50.0).unwrap();
    set_temperatures(&mut desc, &[Some(400.0), Some(300.0)]).unwrap();
    let mut s = settings(Some(0.0), false);
    s.view_factors.form_factors.method = vs.form_factors.method;
    s.environment = 50.0;
    let th = solve(Scene::from_desc(desc).unwrap(), &s, &NoProgress).unwrap();
    for (a, b) in th.surfaces.iter().zip(&table.rows) {
        assert!((a.heat - b.heat).abs() <= 1e-9 * a.heat.abs(), "{} vs {}", a.heat, b.heat);
    }
    assert!((th.environment_heat - table.environment_heat).abs() <= 1e-9 * th.total);
}
