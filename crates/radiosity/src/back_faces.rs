//! Where the light that no surface receives goes: out through openings, or into the back
//! faces of one-sided surfaces.
//!
//! The solvers' energy balance knows only `emitted = absorbed + escaped + unshot`, where
//! "escaped" is everything shot that arrived on no front face: `Σ_i A_i S_i (1 − Σ_j F_ij)`.
//! A closed room whose walls are wound the wrong way loses almost everything that way, and
//! that is not light leaving the scene but a modelling error (issue 9: "escaped 95.46 %"
//! one-sided on a closed office). This module splits the escaped power into the part that
//! hits the back of a one-sided polygon and the part that leaves through openings, with
//! [`PROBES`] cosine-distributed probe rays per element (Halton directions, first hit;
//! fewer on large meshes, [`probes_for`]):
//!
//! ```text
//! back = escaped · Σ_i A_i B_i b_i / Σ_i A_i B_i (b_i + m_i)
//! ```
//!
//! with `b_i`, `m_i` the fractions of element i's probes that hit a back face or nothing.
//! The split is exact in sum (`escaped` loses what `back_faces` gains), an estimate in its
//! proportion; the objects whose back faces take the most are listed for the warning.

use glam::DVec3;
use rayon::prelude::*;

use crate::accel::SceneRays;
use crate::mesh::{Mesh, Receivers};
use crate::sampling::{basis, cosine_hemisphere, halton2};
use crate::scene::Scene;
use crate::solve::EnergyBalance;
use crate::{luminance, Rgb};

/// Probe rays per element.
pub const PROBES: u32 = 16;

/// Probe rays in all above which large meshes take fewer per element (see [`probes_for`]).
pub const PROBE_TOTAL: u64 = 16 * 50_000;

/// The fewest probe rays per element.
pub const MIN_PROBES: u32 = 4;

/// Probe rays per element on a mesh of `n` elements: [`PROBES`], or fewer (down to
/// [`MIN_PROBES`]) where `n × PROBES` would exceed [`PROBE_TOTAL`]. The split is a sum
/// over the elements, so its noise depends on the rays in all: on the conference room's
/// 694 k elements 16 probes each took 2.4 s after the solve, 4 give 2.8 M rays.
pub fn probes_for(n: usize) -> u32 {
    (PROBE_TOTAL / n.max(1) as u64).clamp(MIN_PROBES as u64, PROBES as u64) as u32
}

/// Above this fraction of the emitted power lost into back faces, the user is warned.
pub const WARN_FRACTION: f64 = 0.10;

/// The split, per object.
#[derive(Clone, Debug, Default)]
pub struct BackFaceLoss {
    /// Per object: power absorbed by the back faces of its one-sided polygons.
    pub per_object: Vec<Rgb>,
    /// Probe rays cast.
    pub rays: u64,
}

/// Moves the back-face part of `energy.escaped` into `energy.back_faces` (see the module
/// docs) for the solution `radiosity` on `mesh`; `area` is the open area per element.
pub fn split_escaped(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    receivers: &Receivers,
    radiosity: &[Rgb],
    area: &[f64],
    energy: &mut EnergyBalance,
) -> BackFaceLoss {
    let nobj = scene.objects.len();
    let mut out = BackFaceLoss { per_object: vec![Rgb::ZERO; nobj], rays: 0 };
    if scene.polygons.iter().all(|p| p.two_sided) || mesh.is_empty() {
        return out;
    }
    let diag = scene.diagonal().max(f64::MIN_POSITIVE);
    let probes = probes_for(mesh.len());
    // Per element: (power into back faces, power lost, per-object back hits (object, count)).
    let parts: Vec<(Rgb, Rgb, Vec<(u32, u32)>)> = (0..mesh.len())
        .into_par_iter()
        .with_min_len(64)
        .map(|i| {
            let e = &mesh.elements[i];
            let power = radiosity[i] * area[i];
            if area[i] <= 0.0 || power.max_element() <= 0.0 {
                return (Rgb::ZERO, Rgb::ZERO, Vec::new());
            }
            let x = receivers.points(i, 1).first().copied().unwrap_or(e.centroid);
            let origin = (x + e.normal * (1e-7 * diag)).as_vec3();
            let (t, b) = basis(e.normal);
            let (mut back, mut miss) = (0u32, 0u32);
            let mut hits: Vec<(u32, u32)> = Vec::new();
            for s in 0..probes {
                let (u1, u2) = halton2(s, (0.5 / probes as f64, 0.25));
                let d = cosine_hemisphere(u1, u2);
                let dir: DVec3 = t * d.x + b * d.y + e.normal * d.z;
                match rays.closest_facing(origin, dir.as_vec3(), f32::INFINITY, Some(e.patch)) {
                    None => miss += 1,
                    Some((_, q)) => {
                        let p = &scene.polygons[q as usize];
                        if !p.two_sided && p.normal.dot(dir) > 0.0 {
                            back += 1;
                            match hits.iter_mut().find(|h| h.0 == p.object) {
                                Some(h) => h.1 += 1,
                                None => hits.push((p.object, 1)),
                            }
                        }
                    }
                }
            }
            let f = 1.0 / probes as f64;
            (power * (back as f64 * f), power * ((back + miss) as f64 * f), hits)
        })
        .collect();
    out.rays = probes as u64 * mesh.len() as u64;
    let mut back = Rgb::ZERO;
    let mut lost = Rgb::ZERO;
    let mut per_object = vec![Rgb::ZERO; nobj];
    for (i, (b, l, hits)) in parts.iter().enumerate() {
        back += *b;
        lost += *l;
        let power = radiosity[i] * area[i];
        for &(o, c) in hits {
            per_object[o as usize] += power * (c as f64 / probes as f64);
        }
    }
    let mut moved = Rgb::ZERO;
    for c in 0..3 {
        if lost[c] > 0.0 && energy.escaped[c] > 0.0 {
            moved[c] = energy.escaped[c] * (back[c] / lost[c]).clamp(0.0, 1.0);
        }
    }
    energy.escaped -= moved;
    energy.back_faces += moved;
    // Per object: the moved power shared in proportion to each object's probe hits.
    for c in 0..3 {
        if back[c] > 0.0 {
            for (o, p) in per_object.iter().enumerate() {
                out.per_object[o][c] = p[c] / back[c] * moved[c];
            }
        }
    }
    out
}

/// The warning when more than [`WARN_FRACTION`] of the emitted power goes into back faces,
/// naming the objects that take most of it.
pub fn warning(scene: &Scene, loss: &BackFaceLoss, energy: &EnergyBalance) -> Option<String> {
    let emitted = luminance(energy.emitted);
    let lost = luminance(energy.back_faces);
    if !(emitted > 0.0) || lost <= WARN_FRACTION * emitted {
        return None;
    }
    let mut objs: Vec<(usize, f64)> =
        loss.per_object.iter().enumerate().map(|(o, p)| (o, luminance(*p))).filter(|x| x.1 > 0.0).collect();
    objs.sort_by(|a, b| b.1.total_cmp(&a.1));
    let names: Vec<String> = objs
        .iter()
        .take(5)
        .map(|(o, p)| format!("'{}' {:.1} %", scene.objects[*o].name, 100.0 * p / emitted))
        .collect();
    Some(format!(
        "{:.1} % of the emitted light is absorbed by the back faces of one-sided surfaces (most by {}): \
         the model's faces are probably wound inconsistently; use --two-sided, or two_sided = true per \
         material in a TOML scene (emitters may stay one-sided with two_sided = false)",
        100.0 * lost / emitted,
        names.join(", ")
    ))
}

/// Created power, as a fraction of the emitted, above which [`created_warning`] speaks.
pub const CREATED_WARN_FRACTION: f64 = 0.01;

/// The warning when the books close only with a negative escaped term: the transport
/// delivered more than the surfaces sent (light created, radiosities too bright), beyond
/// [`CREATED_WARN_FRACTION`] of the emitted power. `cause` names what in this run does it.
pub fn created_warning(energy: &EnergyBalance, cause: &str) -> Option<String> {
    let emitted = luminance(energy.emitted);
    let escaped = luminance(energy.escaped);
    if !(emitted > 0.0) || escaped >= -CREATED_WARN_FRACTION * emitted {
        return None;
    }
    Some(format!(
        "the solution created light: escaped is {:.2} % of the emitted power, so the surfaces received more than \
         was sent and read too bright; {cause}",
        100.0 * escaped / emitted
    ))
}

/// The hint when more than [`WARN_FRACTION`] of the emitted power escapes and as much is
/// emitted by the back sides of two-sided emitters (`--two-sided` on a model whose lamps
/// are panels in a ceiling: half their light goes up, out of the room). Names the emitting
/// materials whose back sides emit the most.
pub fn two_sided_emitter_warning(scene: &Scene, energy: &EnergyBalance) -> Option<String> {
    let emitted = luminance(energy.emitted);
    let escaped = luminance(energy.escaped);
    if !(emitted > 0.0) || escaped <= WARN_FRACTION * emitted {
        return None;
    }
    let mut per_material = vec![0.0; scene.materials.len()];
    for p in scene.polygons.iter().filter(|p| p.back_side) {
        let m = p.material as usize;
        per_material[m] += std::f64::consts::PI * luminance(scene.materials[m].emission) * p.area;
    }
    let back: f64 = per_material.iter().sum();
    if back <= WARN_FRACTION * emitted {
        return None;
    }
    let mut mats: Vec<(usize, f64)> = per_material.into_iter().enumerate().filter(|x| x.1 > 0.0).collect();
    mats.sort_by(|a, b| b.1.total_cmp(&a.1));
    let names: Vec<String> =
        mats.iter().take(5).map(|(m, _)| format!("'{}'", scene.materials[*m].name)).collect();
    Some(format!(
        "{:.1} % of the emitted light escapes, and {:.1} % is emitted by the back sides of two-sided emitters \
         ({}): if these lights shine only from their front, keep them one-sided in a TOML scene \
         ([materials.NAME] two_sided = false) while the rest stays two-sided",
        100.0 * escaped / emitted,
        100.0 * back / emitted,
        names.join(", ")
    ))
}
