//! Which side of each two-sided polygon faces the air that light moves through.
//!
//! The coverage test ([`super::coverage`]) reads "inside a closed solid" from the input
//! winding: a probe that meets the generated back copy of a two-sided polygon is inside.
//! With `--two-sided` (for models wound inconsistently) the winding says nothing, and a
//! model with every face reversed (what a mirroring export or a negative scale gives) put
//! its lamps, walls and floor "inside": RenderPark's office2 reversed, `--two-sided`, lost
//! 84 % of its lamp and created 1 % of the light (issue 9).
//!
//! Here light itself tells the sides apart, as photon tracing would (Jensen 1996):
//! paths leave the lights (emitting polygons' input sides, point and spot lights, and a
//! lit sky, sun or directional light from outside the scene's bounds), bounce diffusely off
//! every surface they meet for a few bounces (black ones end them), and count the sides
//! they reach. The verdict is per *surface*: input polygons joined through edges that they
//! alone share and run along in opposite directions (wound alike), so that a column of 500
//! triangles is one decision on all the paths that reach it (reversed Sponza under the sky
//! left 61,000 of its 66,000 pairs unreached one by one). Each path counts once per side of
//! a surface, and a side needs [`MIN_HITS`] paths: a path that leaks into a closed solid
//! through a crack rattles about inside it, and counted at every bounce, Sponza's roof read
//! as lit from inside.
//!
//! A surface whose back copies are reached and whose input sides (almost) never are faces
//! the air with its back: its sides swap roles for the coverage probes (the back copy is a
//! surface; the input side is the inside of a solid where it faces a closed space, and stays
//! a surface where probes from it leave the scene). Surfaces reached on both sides (thin
//! sheets in the air: a trough open at the bottom) are surfaces on both; surfaces reached on
//! neither side (inside solids, dark rooms) or far more on their input side keep the input
//! winding: a model wound correctly keeps it, but for sheets lit on both sides.

use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

use crate::accel::SceneRays;
use rand::RngExt;

use crate::direct::{fan_cdf, sample_polygon};
use crate::sampling::{basis, cosine_hemisphere, rng_for};
use crate::scene::{LightKind, Scene};

/// Bounces per light path.
pub const BOUNCES: usize = 8;

/// Paths per input polygon (the total bounded by [`MIN_PATHS`] and [`MAX_PATHS`]).
pub const PATHS_PER_POLYGON: usize = 2;
/// Fewest light paths.
pub const MIN_PATHS: usize = 65_536;
/// Most light paths.
pub const MAX_PATHS: usize = 262_144;

/// Paths that must reach a side of a surface before it counts as reached: light that
/// leaks into a solid comes in by few paths (6 to the back of Sponza's roof and walls,
/// beside 18 to their fronts, of 133,000), light that reaches a surface by many.
pub const MIN_HITS: u32 = 8;
/// A side counts as unreached beside its twin when its twin has more than this many times
/// its hits.
pub const RATIO: u32 = 16;

/// What a probe that meets one side of a two-sided pair meets, as light showed it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// As the input winding says: the generated back copy is the inside of a solid (light
    /// reached neither side, or the input side far more).
    Winding,
    /// Air: a surface (the side light reached; both sides of a sheet lit from both).
    Air,
    /// The inside of a solid, or the void (the side light never reached, where it reached
    /// the other many times).
    Solid,
}

/// A source of light paths: a point on it and a direction.
enum Source {
    /// An emitting polygon (its index), sampled by area over its fan of triangles
    /// ([`crate::direct::fan_cdf`]).
    Polygon(u32, Vec<f64>),
    /// A point or spot light (all round).
    Point(DVec3),
    /// Light from far away: parallel rays going in `Some(direction)` (a sun, a directional
    /// light), or in every direction whose sky is lit (`None`), over a disk that covers the
    /// scene.
    Far(Option<DVec3>),
}

/// Per polygon, the [`Side`] of each two-sided pair's sides (see the module docs); empty
/// when every side keeps the input winding (or the scene has no two-sided pairs). Light
/// from a sky, a sun or a directional light comes in from outside the scene's bounds.
/// Paths start only at points of emitting
/// polygons that `open` (the coverage test by the input winding, given a point, its normal
/// and its polygon) finds in the air, so that light from a face run into a solid (boxes
/// that interpenetrate in a furnace, every face emitting) does not make that solid's inside
/// air; where `open` finds no such point (a model whose every face is reversed, its lamps
/// read as inside), they start anywhere on the lights.
pub fn sides(scene: &Scene, rays: &SceneRays, open: &(dyn Fn(DVec3, DVec3, u32) -> bool + Sync)) -> Vec<Side> {
    let n = scene.polygons.len();
    if !scene.polygons.iter().any(|p| p.back_side) {
        return Vec::new();
    }
    // Input sides only: a back copy that emits may face the inside of a solid (a furnace,
    // every face emitting), and light from there would mark that inside as air.
    let mut sources: Vec<Source> = Vec::new();
    if let Some(sky) = scene.lit_sky() {
        if sky.has_radiance() {
            sources.push(Source::Far(None));
        }
        if let Some(sun) = sky.lit_sun() {
            sources.push(Source::Far(Some(-sun.direction)));
        }
    }
    for l in scene.lights.iter().filter(|l| l.is_lit()) {
        if let LightKind::Directional { direction } = l.kind {
            sources.push(Source::Far(Some(direction)));
        }
    }
    sources.extend((0..n as u32)
        .filter(|&q| {
            let p = &scene.polygons[q as usize];
            !p.back_side && p.area > 0.0 && scene.materials[p.material as usize].is_emitter()
        })
        .map(|q| Source::Polygon(q, fan_cdf(&scene.polygons[q as usize].vertices))));
    for l in &scene.lights {
        if let LightKind::Point { position } | LightKind::Spot { position, .. } = l.kind {
            sources.push(Source::Point(position));
        }
    }
    if sources.is_empty() {
        return Vec::new();
    }
    let inputs = scene.polygons.iter().filter(|p| !p.back_side).count();
    let paths = (inputs * PATHS_PER_POLYGON).clamp(MIN_PATHS, MAX_PATHS).max(sources.len());
    // Decided per surface (pairs joined by edges they run along in opposite directions,
    // wound alike), from all the hits on it: a column of 500 triangles is one decision,
    // where each triangle alone would need its own paths.
    let (root, members) = surfaces(scene, rays);
    // Each path counts once per side of a surface: a path that leaks into a closed solid
    // through a crack rattles about inside it for every bounce left, and counted each time,
    // Sponza's roof and walls read as lit from inside (8 hits behind, 59 in front).
    let side_of: Vec<u32> = (0..n)
        .map(|q| match (root[q], rays.twin_of(q as u32)) {
            (r, _) if r != u32::MAX => 2 * r,
            (_, Some(f)) if root[f as usize] != u32::MAX => 2 * root[f as usize] + 1,
            _ => 2 * q as u32 + 1,
        })
        .collect();
    let Some(hits) = flood(scene, rays, &sources, paths, &side_of, Some(open)).or_else(|| flood(scene, rays, &sources, paths, &side_of, None)) else {
        return Vec::new();
    };
    // Per surface root: the paths reaching its back copies and its input sides.
    let (mut back, mut front) = (vec![0u32; n], vec![0u32; n]);
    for (f, &r) in root.iter().enumerate() {
        if r != u32::MAX {
            let b = rays.twin_of(f as u32).unwrap() as usize;
            back[r as usize] = back[r as usize].saturating_add(hits[b]);
            front[r as usize] = front[r as usize].saturating_add(hits[f]);
        }
    }
    // A side is reached when at least [`MIN_HITS`] paths come to it, and more than a
    // [`RATIO`]-th of those that come to the other side. By paths, not by the power they
    // carry: the dim outside of a lamp's trough is air all the same.
    let reached = |x: u32, other: u32| x >= MIN_HITS && x.saturating_mul(RATIO) >= other;
    // Per surface root: Some((back copies, input sides)).
    let verdict: Vec<(u32, Side, Side)> = members
        .par_iter()
        .filter_map(|(r, m)| {
            let (bh, fh) = (back[*r as usize], front[*r as usize]);
            match (reached(fh, bh), reached(bh, fh)) {
                // Light reaches the back copies and (almost) never the input sides: swapped,
                // the input sides the inside of a solid where they face a closed space
                // (furniture wound backwards). Where they face open space (the outside of a
                // room wound outward, the top of a sheet under an open ceiling that light
                // reaches only around the world's edge) they stay surfaces: read as a
                // solid, a ceiling over such a sheet was covered.
                (false, true) => {
                    let inside = if faces_closed_space(scene, rays, m, *r) { Side::Solid } else { Side::Winding };
                    Some((*r, Side::Air, inside))
                }
                // A sheet in the air, lit on both sides (a trough open at the bottom, a panel).
                (true, true) => Some((*r, Side::Air, Side::Air)),
                _ => None,
            }
        })
        .collect();
    if verdict.is_empty() {
        return Vec::new();
    }
    let mut sides = vec![Side::Winding; n];
    let mut by_root = vec![None; n];
    for (r, b, f) in verdict {
        by_root[r as usize] = Some((b, f));
    }
    for (f, &r) in root.iter().enumerate() {
        if let Some(Some((sb, sf))) = (r != u32::MAX).then(|| by_root[r as usize]) {
            sides[rays.twin_of(f as u32).unwrap() as usize] = sb;
            sides[f] = sf;
        }
    }
    sides
}

/// Hits per polygon side of `paths` light paths from `sources`, each path counted once
/// per value of `side_of` (per polygon: the side of the surface it belongs to); with
/// `open`, a path whose start point `open` rejects is dropped, and None when every one
/// was.
fn flood(
    scene: &Scene,
    rays: &SceneRays,
    sources: &[Source],
    paths: usize,
    side_of: &[u32],
    open: Option<&(dyn Fn(DVec3, DVec3, u32) -> bool + Sync)>,
) -> Option<Vec<u32>> {
    let diag = scene.diagonal().max(f64::MIN_POSITIVE);
    let (lo, hi) = scene.bounds();
    let (centre, radius) = ((lo + hi) * 0.5, 0.5 * diag * 1.001);
    let hits: Vec<AtomicU32> = (0..scene.polygons.len()).map(|_| AtomicU32::new(0)).collect();
    // A black surface ends a path: it reflects nothing.
    let black: Vec<bool> = scene.materials.iter().map(|m| m.reflectance.max_element() <= 0.0).collect();
    let started = std::sync::atomic::AtomicUsize::new(0);
    (0..paths).into_par_iter().with_min_len(256).for_each(|i| {
        let mut rng = rng_for(0x11_7E_51DE, i as u64);
        let mut u = || rng.random::<f64>();
        let (mut seen, mut k) = ([u32::MAX; BOUNCES + 1], 0);
        let mut count = |q: u32| {
            let s = side_of[q as usize];
            if !seen[..k].contains(&s) {
                seen[k] = s;
                k += 1;
                hits[q as usize].fetch_add(1, Relaxed);
            }
        };

        let source = &sources[i % sources.len()];
        let (mut x, mut n, mut from) = match *source {
            Source::Polygon(q, ref cdf) => {
                let p = &scene.polygons[q as usize];
                (sample_polygon(&p.vertices, cdf, u(), u()), p.normal, Some(q))
            }
            Source::Point(x) => (x, DVec3::ZERO, None),
            Source::Far(dir) => {
                // A direction (the sky's: uniform over the sphere, kept where the sky that
                // it comes from is lit), then a point on the disk across it that covers
                // the scene's bounding sphere, started outside that sphere.
                let d = dir.unwrap_or_else(|| uniform_sphere(u(), u()));
                if dir.is_none() && scene.lit_sky().is_none_or(|s| s.radiance_in(-d, 1e-3).max_element() <= 0.0) {
                    return;
                }
                let (t, b) = basis(d);
                let (r, phi) = (u().sqrt() * radius, std::f64::consts::TAU * u());
                let x = centre + (t * phi.cos() + b * phi.sin()) * r - d * (2.0 * radius);
                match rays.closest_facing(x.as_vec3(), d.as_vec3(), f32::INFINITY, None) {
                    Some((hit, q)) if scene.polygons[q as usize].normal.dot(d) <= 0.0 => {
                        count(q);
                        started.fetch_add(1, Relaxed);
                        (x + d * f64::from(hit.t), scene.polygons[q as usize].normal, Some(q))
                    }
                    _ => return,
                }
            }
        };
        // A far source's path has started (it met the scene); a light's must start in the air.
        if !matches!(source, Source::Far(_)) {
            if let (Some(open), Some(q)) = (open, from) {
                if !open(x, n, q) {
                    return;
                }
            }
            started.fetch_add(1, Relaxed);
        }
        for _ in 0..BOUNCES {
            let dir = if n == DVec3::ZERO {
                uniform_sphere(u(), u())
            } else {
                let (t, b) = basis(n);
                let d = cosine_hemisphere(u(), u());
                t * d.x + b * d.y + n * d.z
            };
            let origin = x + n * (1e-7 * diag);
            let Some((hit, q)) = rays.closest_facing(origin.as_vec3(), dir.as_vec3(), f32::INFINITY, from) else {
                break;
            };
            let qn = scene.polygons[q as usize].normal;
            if qn.dot(dir) > 0.0 {
                // The back of a one-sided surface: it absorbs.
                break;
            }
            count(q);
            if black[scene.polygons[q as usize].material as usize] {
                break;
            }
            x = origin + dir * f64::from(hit.t);
            n = qn;
            from = Some(q);
        }
    });
    (started.into_inner() > 0).then(|| hits.into_iter().map(AtomicU32::into_inner).collect())
}

/// Probes from the input sides of the polygons `members` (of the surface `id`; points
/// spread over them, cosine directions), [`CLOSED_PROBES`] of them: true when none leaves
/// the scene.
fn faces_closed_space(scene: &Scene, rays: &SceneRays, members: &[u32], id: u32) -> bool {
    let diag = scene.diagonal().max(f64::MIN_POSITIVE);
    let mut rng = rng_for(0xC1_05ED, u64::from(id));
    let mut u = || rng.random::<f64>();
    (0..CLOSED_PROBES).all(|_| {
        let q = members[((u() * members.len() as f64) as usize).min(members.len() - 1)];
        let p = &scene.polygons[q as usize];
        let (t, b) = basis(p.normal);
        let x = sample_polygon(&p.vertices, &fan_cdf(&p.vertices), u(), u()) + p.normal * (1e-7 * diag);
        let d = cosine_hemisphere(u(), u());
        let dir = t * d.x + b * d.y + p.normal * d.z;
        rays.closest_facing(x.as_vec3(), dir.as_vec3(), f32::INFINITY, Some(q)).is_some()
    })
}

/// Surfaces of two-sided pairs: per polygon, the root of the input side's surface
/// (`u32::MAX` for back copies and polygons without a twin), and each root with its input
/// sides. Two input sides join where they share an edge that no third input polygon has
/// and run along it in opposite directions (wound alike).
fn surfaces(scene: &Scene, rays: &SceneRays) -> (Vec<u32>, Vec<(u32, Vec<u32>)>) {
    use std::collections::HashMap;
    let n = scene.polygons.len();
    let paired = |q: usize| !scene.polygons[q].back_side && rays.twin_of(q as u32).is_some();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    // Per undirected edge: the input sides on it, with whether each runs along it from the
    // key's first vertex.
    let mut edges: HashMap<super::coverage::EdgeKey, Vec<(u32, bool)>> = HashMap::new();
    for (q, p) in scene.polygons.iter().enumerate().filter(|(_, p)| !p.back_side) {
        let v = &p.vertices;
        for k in 0..v.len() {
            let (a, b) = (v[k], v[(k + 1) % v.len()]);
            let key = super::coverage::edge_key(a, b);
            let forward = a.to_array().map(super::uniform::round_key) == key.0;
            edges.entry(key).or_default().push((q as u32, forward));
        }
    }
    for on in edges.values() {
        if let [(a, fa), (b, fb)] = on[..] {
            if fa != fb && paired(a as usize) && paired(b as usize) {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                if ra != rb {
                    parent[ra as usize] = rb;
                }
            }
        }
    }
    let mut root = vec![u32::MAX; n];
    let mut members: HashMap<u32, Vec<u32>> = HashMap::new();
    for q in (0..n).filter(|&q| paired(q)) {
        let r = find(&mut parent, q as u32);
        root[q] = r;
        members.entry(r).or_default().push(q as u32);
    }
    let mut members: Vec<(u32, Vec<u32>)> = members.into_iter().collect();
    members.sort_unstable_by_key(|(r, _)| *r);
    (root, members)
}

/// Probes of [`faces_closed_space`] per surface.
pub const CLOSED_PROBES: u32 = 32;

/// A direction uniform on the unit sphere for (u1, u2) ∈ [0,1)².
fn uniform_sphere(u1: f64, u2: f64) -> DVec3 {
    let (z, phi) = (1.0 - 2.0 * u1, std::f64::consts::TAU * u2);
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}
