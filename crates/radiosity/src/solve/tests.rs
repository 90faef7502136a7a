//! Tests of every solver against `direct` and against closed forms (furnace box).
//!
//! The Cornell box is meshed at a few hundred elements and its point-sampled form factors
//! are computed once. Those factors are reciprocal only approximately; every deterministic
//! solver (shooting included: it reads columns of F) must agree with `direct` both on them
//! and on the symmetrised operator `A_i F'_ij = (A_i F_ij + A_j F_ji)/2`.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

use super::*;
use crate::accel::SceneRays;
use crate::mesh::{mesh_uniform, Mesh};
use crate::pipeline::element_materials;
use crate::progress::StopFlag;
use crate::scene::{builtin, Scene};
use crate::{form_factor, NoProgress};

struct Fixture {
    scene: Scene,
    mesh: Mesh,
    rows: SparseRows,
    symmetric: SparseRows,
    rho: Vec<Rgb>,
    emission: Vec<Rgb>,
    area: Vec<f64>,
}

impl Fixture {
    fn new(scene: Scene, size: f64) -> Fixture {
        let mesh = mesh_uniform(&scene, size);
        let rays = SceneRays::new(&scene.polygons);
        // No coverage (every receiver point open): the stochastic solvers, compared with
        // these factors, do not model contact coverage either.
        let receivers = crate::mesh::Receivers::all_open(&mesh);
        let (rows, _) =
            form_factor::compute(&scene, &mesh, &rays, &receivers, &form_factor::Options::default(), &NoProgress).unwrap();
        let area: Vec<f64> = mesh.elements.iter().map(|e| e.area).collect();
        let symmetric = symmetrise(&rows, &area);
        let (rho, emission) = element_materials(&scene, &mesh);
        Fixture { scene, mesh, rows, symmetric, rho, emission, area }
    }
    fn system<'a>(&'a self, t: &'a SparseRows) -> System<'a> {
        System { transport: t, reflectance: &self.rho, emission: &self.emission, area: &self.area }
    }
}

/// `F'_ij = (A_i F_ij + A_j F_ji) / (2 A_i)`: exactly reciprocal.
fn symmetrise(f: &SparseRows, area: &[f64]) -> SparseRows {
    let t = f.transpose();
    let n = f.n();
    let rows = (0..n)
        .map(|i| {
            let mut m: std::collections::BTreeMap<u32, f64> = Default::default();
            let (c, v) = f.row(i);
            for (&j, &x) in c.iter().zip(v) {
                *m.entry(j).or_default() += 0.5 * x as f64;
            }
            // Column i of F = row i of the transpose: F_ji.
            let (c, v) = t.row(i);
            for (&j, &x) in c.iter().zip(v) {
                *m.entry(j).or_default() += 0.5 * x as f64 * area[j as usize] / area[i];
            }
            m.into_iter().map(|(j, x)| (j, x as f32)).collect()
        })
        .collect();
    SparseRows::from_rows(rows)
}

/// The Cornell box at a few hundred elements.
fn cornell() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| Fixture::new(Scene::from_desc(builtin::cornell()).unwrap(), 110.0))
}

/// The furnace box (ρ = 0.5, L_e = 1 everywhere; B = 2π exactly), 6 × 6 elements a wall.
/// The furnace tests the solvers, not the form factors: its operator is made an exact
/// enclosure (reciprocal, rows summing to one) by [`enclosure`], because the point-sampled
/// rows only sum to 1 ± 5 % at this resolution (each pair draws its own receiver points).
fn furnace() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let mut f = Fixture::new(Scene::from_desc(builtin::furnace(0.5, 1.0)).unwrap(), 1.0 / 6.0);
        f.rows = enclosure(&f.rows, &f.area);
        f.symmetric = f.rows.clone();
        f
    })
}

/// The nearest exact enclosure: `G = A·F` symmetrised, then scaled `G ← D G D` until every
/// row of `F' = G / A` sums to one (symmetric Sinkhorn balancing).
fn enclosure(f: &SparseRows, area: &[f64]) -> SparseRows {
    let s = symmetrise(f, area);
    let n = s.n();
    let mut g: Vec<Vec<(u32, f64)>> =
        (0..n).map(|i| { let (c, v) = s.row(i); c.iter().zip(v).map(|(&j, &x)| (j, x as f64 * area[i])).collect() }).collect();
    for _ in 0..200 {
        let d: Vec<f64> = (0..n).map(|i| (area[i] / g[i].iter().map(|e| e.1).sum::<f64>()).sqrt()).collect();
        for i in 0..n {
            for e in g[i].iter_mut() {
                e.1 *= d[i] * d[e.0 as usize];
            }
        }
    }
    SparseRows::from_rows(g.into_iter().enumerate().map(|(i, r)| r.into_iter().map(|(j, x)| (j, (x / area[i]) as f32)).collect()).collect())
}

/// An open box (no front wall) with a light ceiling and coloured walls, 5 × 5 elements a
/// wall, with form factors accurate to about 1e-4: no occlusion, so F_ij is the exact
/// point-to-polygon factor averaged over 16 × 16 midpoints of the receiver. The stochastic
/// solvers, which estimate the exact-F solution, must agree with its direct solution
/// within their reported error.
fn open_box() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        use crate::scene::MaterialDesc;
        let mut d = builtin::furnace(0.5, 0.0);
        d.materials = vec![
            MaterialDesc::diffuse("white", Rgb::splat(0.7)),
            MaterialDesc { emission: Rgb::new(4.0, 3.0, 2.0), ..MaterialDesc::diffuse("light", Rgb::splat(0.2)) },
            MaterialDesc::diffuse("red", Rgb::new(0.6, 0.1, 0.1)),
            MaterialDesc::diffuse("green", Rgb::new(0.1, 0.6, 0.1)),
        ];
        for (p, m) in d.polygons.iter_mut().zip([0, 1, 2, 3, 0, 0]) {
            p.material = m;
        }
        d.polygons.pop(); // the front wall: light escapes
        let scene = Scene::from_desc(d).unwrap();
        let mesh = mesh_uniform(&scene, 0.2);
        let n = mesh.len();
        const K: usize = 16;
        let rows = (0..n)
            .map(|i| {
                let ei = &mesh.elements[i];
                let mut row = Vec::new();
                for j in 0..n {
                    let ej = &mesh.elements[j];
                    if ej.patch == ei.patch {
                        continue;
                    }
                    let (c, nv) = ej.corners(&mesh.positions);
                    let mut sum = 0.0;
                    for a in 0..K {
                        for b in 0..K {
                            let x = ei.point(&mesh.positions, (a as f64 + 0.5) / K as f64, (b as f64 + 0.5) / K as f64);
                            sum += crate::geom::kernel::point_to_polygon(x, ei.normal, &c[..nv], ej.normal);
                        }
                    }
                    if sum > 0.0 {
                        row.push((j as u32, (sum / (K * K) as f64) as f32));
                    }
                }
                row
            })
            .collect();
        let rows = SparseRows::from_rows(rows);
        let area: Vec<f64> = mesh.elements.iter().map(|e| e.area).collect();
        let symmetric = symmetrise(&rows, &area);
        let (rho, emission) = element_materials(&scene, &mesh);
        Fixture { scene, mesh, rows, symmetric, rho, emission, area }
    })
}

fn tight() -> Options {
    Options { tolerance: 1e-11, max_iterations: 100_000, ..Default::default() }
}

const DETERMINISTIC: [Solver; 6] = [Solver::Direct, Solver::Jacobi, Solver::Chebyshev, Solver::GaussSeidel, Solver::Shooting, Solver::Progressive];

#[test]
fn names_round_trip() {
    for s in Solver::ALL {
        assert_eq!(s.name().parse::<Solver>().unwrap(), s);
    }
    assert!("gauss_seidel".parse::<Solver>().is_err());
}

#[test]
fn cornell_fixture_has_a_few_hundred_elements() {
    let n = cornell().mesh.len();
    assert!((200..=600).contains(&n), "{n} elements");
}

#[test]
fn every_deterministic_solver_agrees_with_direct_on_a_reciprocal_operator() {
    let f = cornell();
    let sys = f.system(&f.symmetric);
    let direct = solve(Solver::Direct, &sys, &tight(), &NoProgress).unwrap();
    assert!(direct.stats.residual < 1e-12, "direct residual {}", direct.stats.residual);
    for s in DETERMINISTIC {
        let sol = solve(s, &sys, &tight(), &NoProgress).unwrap();
        assert_eq!(sol.stats.stop, StopReason::Converged, "{s}");
        let d = max_relative_difference(&sol.radiosity, &direct.radiosity);
        eprintln!("reciprocal F, {s}: max relative difference from direct {d:.2e}");
        assert!(d <= 1e-5, "{s}: max relative difference from direct {d:.3e}");
    }
}

#[test]
fn every_deterministic_solver_agrees_with_direct_on_the_point_sampled_operator() {
    let f = cornell();
    let sys = f.system(&f.rows);
    let direct = solve(Solver::Direct, &sys, &tight(), &NoProgress).unwrap();
    for s in DETERMINISTIC {
        let sol = solve(s, &sys, &tight(), &NoProgress).unwrap();
        let d = max_relative_difference(&sol.radiosity, &direct.radiosity);
        eprintln!("point-sampled F, {s}: max relative difference from direct {d:.2e}");
        assert!(d <= 1e-6, "{s}: max relative difference from direct {d:.3e}");
    }
}

#[test]
fn furnace_every_deterministic_solver_gives_e_over_one_minus_rho() {
    let f = furnace();
    let exact = 2.0 * std::f64::consts::PI;
    for t in [&f.rows, &f.symmetric] {
        let sys = f.system(t);
        for s in DETERMINISTIC {
            let sol = solve(s, &sys, &Options { tolerance: 1e-10, ..tight() }, &NoProgress).unwrap();
            let worst = sol.radiosity.iter().map(|b| ((*b - Rgb::splat(exact)).abs() / exact).max_element()).fold(0.0, f64::max);
            eprintln!("furnace, {s}: max relative error of B {worst:.2e}, imbalance {:.1e}", sol.energy.relative_imbalance());
            assert!(worst <= 1e-6, "{s}: furnace B off by {worst:.3e} relative");
            // A closed box: nothing escapes, and what is emitted is absorbed.
            let e = &sol.energy;
            assert!(e.relative_imbalance() <= 1e-6, "{s}: imbalance {:.3e}", e.relative_imbalance());
            let absorbed = (e.absorbed / e.emitted - Rgb::ONE).abs().max_element();
            assert!(absorbed <= 1e-6, "{s}: absorbed/emitted − 1 = {absorbed:.3e}");
        }
    }
}

#[test]
fn one_jacobi_iteration_lights_only_what_the_emitters_see() {
    let f = cornell();
    let sys = f.system(&f.rows);
    let one = solve(Solver::Jacobi, &sys, &Options { max_iterations: 1, ..tight() }, &NoProgress).unwrap();
    assert_eq!(one.stats.iterations, 1);
    let emitters: Vec<bool> = f.emission.iter().map(|e| e.max_element() > 0.0).collect();
    let mut lit = 0;
    for i in 0..f.mesh.len() {
        let (c, _) = f.rows.row(i);
        let sees_light = c.iter().any(|&j| emitters[j as usize]);
        if sees_light {
            assert!((one.radiosity[i] - f.emission[i]).min_element() > 0.0, "element {i} sees the light but is not lit");
            lit += 1;
        } else {
            assert_eq!(one.radiosity[i], f.emission[i], "element {i} cannot see the light but was lit");
        }
    }
    // The ceiling is coplanar with the light: dark after one bounce, lit after two.
    let ceiling: Vec<usize> = (0..f.mesh.len())
        .filter(|&i| f.scene.objects[f.scene.polygons[f.mesh.elements[i].patch as usize].object as usize].name.starts_with("ceiling"))
        .collect();
    assert!(!ceiling.is_empty() && lit > f.mesh.len() / 2);
    assert!(ceiling.iter().all(|&i| one.radiosity[i] == Rgb::ZERO));
    let two = solve(Solver::Jacobi, &sys, &Options { max_iterations: 2, ..tight() }, &NoProgress).unwrap();
    assert!(ceiling.iter().all(|&i| two.radiosity[i].min_element() > 0.0));
}

#[test]
fn gauss_seidel_needs_fewer_sweeps_than_jacobi() {
    let f = cornell();
    let sys = f.system(&f.rows);
    let opts = Options { tolerance: 1e-6, ..tight() };
    let j = solve(Solver::Jacobi, &sys, &opts, &NoProgress).unwrap();
    let gs = solve(Solver::GaussSeidel, &sys, &opts, &NoProgress).unwrap();
    assert_eq!(gs.stats.stop, StopReason::Converged);
    eprintln!("to 1e-6: Gauss-Seidel {} sweeps, Jacobi {}", gs.stats.iterations, j.stats.iterations);
    assert!(gs.stats.iterations < j.stats.iterations, "Gauss–Seidel {} sweeps, Jacobi {}", gs.stats.iterations, j.stats.iterations);
    // And its residual bookkeeping is the true residual of its iterate.
    let true_residual = sys.residual(&gs.radiosity);
    assert!((true_residual - gs.stats.residual).abs() <= 1e-9 + 1e-6 * true_residual);
}

/// Chebyshev's recurrence needs far fewer sweeps than Jacobi for the same tolerance, on
/// the Cornell box (spectral radius of ρF about 0.6) and in the furnace (0.5), and its
/// reported residual is the true residual of its iterate.
#[test]
fn chebyshev_needs_fewer_sweeps_than_jacobi() {
    for (name, f) in [("cornell", cornell()), ("furnace", furnace())] {
        let sys = f.system(&f.rows);
        for tolerance in [1e-4, 1e-8] {
            let opts = Options { tolerance, ..tight() };
            let j = solve(Solver::Jacobi, &sys, &opts, &NoProgress).unwrap();
            let c = solve(Solver::Chebyshev, &sys, &opts, &NoProgress).unwrap();
            assert_eq!(c.stats.stop, StopReason::Converged);
            let (nc, nj) = (c.stats.iterations, j.stats.iterations);
            eprintln!("{name}, to {tolerance:e}: Chebyshev {nc} sweeps, Jacobi {nj}");
            assert!((nc as f64) <= 0.75 * nj as f64, "{name}, to {tolerance:e}: Chebyshev {nc} sweeps, Jacobi {nj}");
            let true_residual = sys.residual(&c.radiosity);
            assert!((true_residual - c.stats.residual).abs() <= 1e-12 + 1e-6 * true_residual);
            assert!(true_residual <= tolerance);
        }
    }
}

/// A cycle of three elements (each sees only the next) has complex eigenvalues
/// `0.9·e^{±2πi/3}`, off the real interval Chebyshev's recurrence assumes: the residual
/// rises under it, the recurrence restarts and falls back to Jacobi, and the solve still
/// reaches the direct solution, never reported as diverging.
#[test]
fn chebyshev_falls_back_to_jacobi_where_the_spectrum_is_complex() {
    let rows = SparseRows::from_rows(vec![vec![(1, 1.0)], vec![(2, 1.0)], vec![(0, 1.0)]]);
    let rho = vec![Rgb::splat(0.9); 3];
    let e = vec![Rgb::ONE, Rgb::ZERO, Rgb::ZERO];
    let area = vec![1.0; 3];
    let sys = System { transport: &rows, reflectance: &rho, emission: &e, area: &area };
    let direct = solve(Solver::Direct, &sys, &tight(), &NoProgress).unwrap();
    let c = solve(Solver::Chebyshev, &sys, &Options { tolerance: 1e-10, ..tight() }, &NoProgress).unwrap();
    assert_eq!(c.stats.stop, StopReason::Converged);
    let d = max_relative_difference(&c.radiosity, &direct.radiosity);
    eprintln!("3-cycle: Chebyshev {} sweeps, max relative difference from direct {d:.2e}", c.stats.iterations);
    assert!(d <= 1e-8, "{d:e}");
}

#[test]
fn shooting_conserves_power() {
    let f = cornell();
    let sys = f.system(&f.rows);
    // Part-way (most power unshot) and converged: the books close either way.
    for max_iterations in [1, 3, 100_000] {
        let sol = solve(Solver::Shooting, &sys, &Options { max_iterations, ..tight() }, &NoProgress).unwrap();
        let e = &sol.energy;
        eprintln!("shooting, {max_iterations} sweeps: imbalance {:.1e}", e.relative_imbalance());
        assert!(e.relative_imbalance() <= 1e-9, "after {max_iterations} sweeps: imbalance {:.3e}", e.relative_imbalance());
        // The Cornell box is open at the front: some power escapes.
        assert!(e.escaped.min_element() > 0.01 * e.emitted.min_element());
        if max_iterations == 1 {
            assert!(luminance(e.unshot) > 0.01 * luminance(e.emitted));
        }
    }
}

#[test]
fn every_solver_energy_balance_closes_and_unshot_matches_the_residual() {
    let f = cornell();
    let sys = f.system(&f.rows);
    for s in DETERMINISTIC {
        for max_iterations in [2, 100_000] {
            let sol = solve(s, &sys, &Options { max_iterations, ..tight() }, &NoProgress).unwrap();
            let e = &sol.energy;
            assert!(e.relative_imbalance() <= 1e-9, "{s}: imbalance {:.3e}", e.relative_imbalance());
            if max_iterations > 2 {
                assert!(luminance(e.unshot).abs() <= 1e-9 * luminance(e.emitted), "{s}: converged but unshot {:?}", e.unshot);
            }
        }
    }
}

#[test]
fn direct_refuses_large_systems_with_the_memory_it_needs() {
    let f = cornell();
    let sys = f.system(&f.rows);
    let opts = Options { direct_memory_limit: 1000, ..Default::default() };
    let err = solve(Solver::Direct, &sys, &opts, &NoProgress).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::TooLarge { needed, .. } if needed == direct::memory_bytes(f.mesh.len())));
    assert!(msg.contains("gauss-seidel") && msg.contains("KiB"), "{msg}");
}

#[test]
fn observer_sees_every_bounce_and_an_interrupt_keeps_the_last_iterate() {
    let f = cornell();
    let sys = f.system(&f.rows);
    for s in [Solver::Jacobi, Solver::GaussSeidel, Solver::Shooting] {
        let stop = StopFlag::default();
        let mut seen = Vec::new();
        let mut obs = |st: &IterationState| {
            seen.push((st.iteration, st.residual, st.radiosity.iter().map(|b| luminance(*b)).sum::<f64>()));
            if st.iteration == 3 {
                stop.stop();
            }
        };
        let sol = solve_observed(s, &sys, &tight(), &stop, Some(&mut obs)).unwrap();
        assert_eq!(sol.stats.stop, StopReason::Interrupted, "{s}");
        assert_eq!(sol.stats.iterations, 3, "{s}");
        assert_eq!(seen.iter().map(|x| x.0).collect::<Vec<_>>(), vec![1, 2, 3], "{s}");
        // Light only flows in: residual falls, total radiosity grows.
        assert!(seen.windows(2).all(|w| w[1].1 < w[0].1 && w[1].2 > w[0].2), "{s}: {seen:?}");
        assert_eq!(sol.stats.residual, seen[2].1);
        assert_eq!(sol.stats.history.len(), 3);
    }
}

#[test]
fn progressive_observer_and_ambient() {
    let f = cornell();
    let sys = f.system(&f.rows);
    let calls = AtomicUsize::new(0);
    let mut first: Option<Vec<Rgb>> = None;
    let mut obs = |st: &IterationState| {
        calls.fetch_add(1, Ordering::Relaxed);
        if first.is_none() {
            first = Some(st.radiosity.to_vec());
        }
    };
    let sol = solve_observed(Solver::Progressive, &sys, &Options { tolerance: 1e-3, ..tight() }, &NoProgress, Some(&mut obs)).unwrap();
    assert!(calls.load(Ordering::Relaxed) >= 4);
    // After one shot the display already has light everywhere thanks to the ambient term.
    let first = first.unwrap();
    assert!(first.iter().zip(&f.rho).all(|(b, r)| b.min_element() > 0.0 || r.min_element() == 0.0));
    let amb = sol.ambient.as_ref().unwrap();
    let amb_power: f64 = amb.iter().zip(&f.area).map(|(a, ar)| luminance(*a) * ar).sum();
    assert!(amb_power > 0.0 && amb_power < 1e-2 * luminance(sol.energy.emitted));
}

#[test]
fn time_budget_stops_every_solver() {
    let f = cornell();
    let sys = f.system(&f.rows);
    let opts = Options { time_budget: Some(Duration::ZERO), ..tight() };
    for s in [Solver::Jacobi, Solver::Chebyshev, Solver::GaussSeidel, Solver::Shooting, Solver::Progressive] {
        let sol = solve(s, &sys, &opts, &NoProgress).unwrap();
        assert_eq!(sol.stats.stop, StopReason::TimeBudget, "{s}");
        assert_eq!(sol.radiosity, f.emission, "{s}");
    }
}

// ---- stochastic solvers ----

fn ray_solve(f: &Fixture, solver: Solver, rays: u64, seed: u64, tolerance: f64) -> Solution {
    let scene_rays = SceneRays::new(&f.scene.polygons);
    let area: Vec<f64> = f.mesh.elements.iter().map(|e| e.area).collect();
    let receivers = crate::mesh::Receivers::all_open(&f.mesh);
    let sys = RaySystem { mesh: &f.mesh, rays: &scene_rays, reflectance: &f.rho, emission: &f.emission, receivers: &receivers, area: &area };
    let opts = Options { tolerance, seed, rays: Some(rays), max_iterations: 200, ..Default::default() };
    stochastic::solve(solver, &sys, &opts, &NoProgress, None).unwrap()
}

#[test]
fn stochastic_solvers_agree_with_direct_within_their_reported_error() {
    // Accurate form factors: the difference is the stochastic error alone.
    let f = open_box();
    let direct = solve(Solver::Direct, &f.system(&f.rows), &tight(), &NoProgress).unwrap();
    for s in [Solver::StochasticJacobi, Solver::StochasticShooting] {
        let sol = ray_solve(f, s, 400_000, 1, 1e-5);
        let err = sol.stats.error_estimate.unwrap();
        let d = relative_difference(&f.area, &sol.radiosity, &direct.radiosity);
        eprintln!("open box, {s}: difference from direct {d:.5}, reported error {err:.5}, {} rays", sol.stats.rays);
        assert!(err > 0.0 && err < 0.01, "{s}: error estimate {err}");
        assert!(d <= 2.0 * err, "{s}: difference from direct {d:.5} vs reported error {err:.5}");
        assert!(sol.energy.relative_imbalance() <= 1e-9, "{s}: imbalance {:.3e}", sol.energy.relative_imbalance());
        assert!(sol.energy.escaped.min_element() > 0.05 * sol.energy.emitted.min_element());
    }
}

#[test]
fn stochastic_solvers_agree_with_direct_on_the_cornell_box() {
    // The point-sampled factors have their own noise: measure it from a second seed and
    // allow for it (see the module docs of form_factor::point_sampled).
    let f = cornell();
    let direct = solve(Solver::Direct, &f.system(&f.rows), &tight(), &NoProgress).unwrap();
    let rays = SceneRays::new(&f.scene.polygons);
    let receivers = crate::mesh::Receivers::all_open(&f.mesh);
    let opts = form_factor::Options { seed: 1, ..Default::default() };
    let (rows2, _) = form_factor::compute(&f.scene, &f.mesh, &rays, &receivers, &opts, &NoProgress).unwrap();
    let direct2 = solve(Solver::Direct, &f.system(&rows2), &tight(), &NoProgress).unwrap();
    let ff_noise = relative_difference(&f.area, &direct.radiosity, &direct2.radiosity) / 2f64.sqrt();
    let mut sols = Vec::new();
    for s in [Solver::StochasticJacobi, Solver::StochasticShooting] {
        let sol = ray_solve(f, s, 400_000, 1, 1e-4);
        let err = sol.stats.error_estimate.unwrap();
        let d = relative_difference(&f.area, &sol.radiosity, &direct.radiosity);
        eprintln!("cornell, {s}: difference from direct {d:.4}, reported error {err:.4}, form-factor noise {ff_noise:.4}");
        assert!(err > 0.0 && err < 0.01, "{s}: error estimate {err}");
        assert!(d <= 2.0 * (err * err + ff_noise * ff_noise).sqrt(), "{s}: {d:.4} vs {err:.4} ⊕ {ff_noise:.4}");
        assert!(sol.energy.relative_imbalance() <= 1e-9);
        sols.push(sol);
    }
    // Both estimate the same (exact-F) solution.
    let d = relative_difference(&f.area, &sols[0].radiosity, &sols[1].radiosity);
    let e = sols[0].stats.error_estimate.unwrap().hypot(sols[1].stats.error_estimate.unwrap());
    assert!(d <= 2.0 * e, "stochastic-jacobi vs stochastic-shooting {d:.5}, errors ⊕ {e:.5}");
}

#[test]
fn stochastic_error_falls_as_one_over_sqrt_rays() {
    let f = furnace();
    let exact = vec![Rgb::splat(2.0 * std::f64::consts::PI); f.mesh.len()];
    for s in [Solver::StochasticJacobi, Solver::StochasticShooting] {
        let few = ray_solve(f, s, 25_000, 7, 1e-5);
        let many = ray_solve(f, s, 400_000, 7, 1e-5);
        let (d1, d2) = (relative_difference(&f.area, &few.radiosity, &exact), relative_difference(&f.area, &many.radiosity, &exact));
        let (e1, e2) = (few.stats.error_estimate.unwrap(), many.stats.error_estimate.unwrap());
        eprintln!("{s}: 16× rays: error {d1:.4} → {d2:.4} (ratio {:.2}); reported {e1:.4} → {e2:.4}", d1 / d2);
        // 16× the rays: 4× smaller error, within the scatter of one seed.
        assert!((2.5..=6.5).contains(&(d1 / d2)), "{s}: error ratio {:.2}", d1 / d2);
        assert!((2.5..=6.5).contains(&(e1 / e2)), "{s}: reported error ratio {:.2}", e1 / e2);
        assert!(d1 <= 2.0 * e1 && d2 <= 2.0 * e2, "{s}: {d1} vs {e1}, {d2} vs {e2}");
    }
}

#[test]
fn stochastic_results_do_not_depend_on_the_thread_count() {
    let f = cornell();
    for s in [Solver::StochasticJacobi, Solver::StochasticShooting] {
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| ray_solve(f, s, 100_000, 3, 1e-3))
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.radiosity, b.radiosity, "{s}");
        assert_eq!(a.stats.rays, b.stats.rays);
        let c = ray_solve(f, s, 100_000, 4, 1e-3);
        assert_ne!(a.radiosity, c.radiosity, "{s}: the seed changes nothing");
    }
}

#[test]
fn locator_finds_the_element_of_points_on_every_patch() {
    for f in [cornell(), open_box()] {
        let loc = crate::mesh::Locator::new(&f.mesh);
        for (k, e) in f.mesh.elements.iter().enumerate() {
            for (u, v) in [(0.5, 0.5), (0.01, 0.02), (0.97, 0.9), (0.3, 0.99)] {
                let p = e.point(&f.mesh.positions, u, v);
                assert_eq!(loc.locate(&f.mesh, e.patch, p), k as u32, "element {k} at ({u}, {v})");
            }
        }
    }
}

/// Issue 9: a system whose rows sum above 1 (what bad form factors gave on touching boxes)
/// must stop with an error naming the cause, not run to 1e140 and return it.
#[test]
fn diverging_system_is_an_error_naming_the_cause() {
    let rows = SparseRows::from_rows(vec![vec![(1, 1.5)], vec![(0, 1.5)]]);
    let rho = vec![Rgb::splat(0.9); 2];
    let e = vec![Rgb::ONE; 2];
    let area = vec![1.0; 2];
    let sys = System { transport: &rows, reflectance: &rho, emission: &e, area: &area };
    for s in [Solver::Jacobi, Solver::Chebyshev, Solver::GaussSeidel, Solver::Shooting, Solver::Progressive, Solver::Direct] {
        match solve(s, &sys, &Options { max_iterations: 10_000, ..Default::default() }, &NoProgress) {
            Err(Error::Diverged { why, elements, .. }) => {
                eprintln!("{s}: {why}");
                assert!(why.contains("bound") || why.contains("rose") || why.contains("residual is") || why.contains("negative"), "{s}: {why}");
                assert!(!elements.is_empty(), "{s}: names the worst elements");
            }
            Err(e) => panic!("{s}: unexpected error {e}"),
            Ok(sol) => panic!("{s}: returned a solution with residual {}", sol.stats.residual),
        }
    }
}

/// NaN or infinity never enters a solve unnoticed.
#[test]
fn non_finite_solver_input_is_refused() {
    let rows = SparseRows::from_rows(vec![vec![(1, 0.5)], vec![(0, 0.5)]]);
    let rho = vec![Rgb::splat(0.5); 2];
    let area = vec![1.0; 2];
    for bad in [f64::NAN, f64::INFINITY, -1.0] {
        let e = vec![Rgb::ONE, Rgb::splat(bad)];
        let sys = System { transport: &rows, reflectance: &rho, emission: &e, area: &area };
        let err = solve(Solver::Jacobi, &sys, &Options::default(), &NoProgress).unwrap_err().to_string();
        assert!(err.contains("emission of element 1"), "{err}");
    }
}
