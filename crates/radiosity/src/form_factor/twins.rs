//! Coincident twins: polygons in one plane, facing the same way, that overlap (a rug on
//! a floor, the back copy of a two-sided box's bottom on the floor it stands on). Methods
//! that test visibility per polygon would count their overlap twice; the lower number owns
//! it (point-sampled and adaptive factors).

use glam::{DVec2, DVec3};

use crate::geom::{bounds_2d, PlaneFrame};
use crate::scene::Polygon;

/// For every polygon, the lower-numbered polygons that lie in the same plane, face the
/// same way and overlap it with positive area ("coincident twins": a rug on a floor, the
/// back copy of a two-sided box's bottom on the floor it stands on). From any point, both
/// members of such a pair are visible where they overlap, so methods that test
/// visibility per polygon would count the overlap twice; the lower number owns it.
/// Candidates are grouped by normal (quantised to 1e-3, looking in the neighbouring
/// cells too, so that no pair is lost at a cell boundary), matched by normal (to 1e-9) and
/// plane offset (to 10·`eps`) within those groups (sorted by offset), then tested by
/// separating axes in the plane. (A hash on the quantised offset lost pairs whose offsets
/// fell on either side of a bin edge: a desk top's underside and the top of a slab under
/// it in office2, issue 9.)
pub fn coincident_twins(polys: &[Polygon], eps: f64) -> Vec<Vec<u32>> {
    use std::collections::HashMap;
    let mut out = vec![Vec::new(); polys.len()];
    let key = |n: DVec3| [(n.x * 1e3).round() as i64, (n.y * 1e3).round() as i64, (n.z * 1e3).round() as i64];
    let offset = |p: &Polygon| p.normal.dot(p.vertices[0]);
    let mut groups: HashMap<[i64; 3], Vec<(f64, u32)>> = HashMap::new();
    for (k, p) in polys.iter().enumerate() {
        groups.entry(key(p.normal)).or_default().push((offset(p), k as u32));
    }
    for g in groups.values_mut() {
        g.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    let tol = 10.0 * eps.max(f64::MIN_POSITIVE);
    let flat = |p: &Polygon, frame: &PlaneFrame| -> Vec<DVec2> { p.vertices.iter().map(|v| frame.to_2d(*v)).collect() };
    for (a, pa) in polys.iter().enumerate() {
        let (n, d) = (pa.normal, offset(pa));
        let k = key(n);
        let mut frame_a: Option<(PlaneFrame, Vec<DVec2>, (DVec2, DVec2))> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(g) = groups.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else { continue };
                    let start = g.partition_point(|x| x.0 < d - tol);
                    for &(db, b) in &g[start..] {
                        if db > d + tol {
                            break;
                        }
                        let pb = &polys[b as usize];
                        if b as usize >= a || pb.normal.dot(n) < 1.0 - 1e-9 {
                            continue;
                        }
                        let (frame, fa, (la, ha)) = frame_a.get_or_insert_with(|| {
                            let frame = PlaneFrame::new(pa.vertices[0], n);
                            let fa = flat(pa, &frame);
                            let bx = bounds_2d(&fa);
                            (frame, fa, bx)
                        });
                        let fb = flat(pb, frame);
                        let (lb, hb) = bounds_2d(&fb);
                        if la.x >= hb.x - eps || lb.x >= ha.x - eps || la.y >= hb.y - eps || lb.y >= ha.y - eps {
                            continue;
                        }
                        if convex_overlap_2d(fa, &fb, eps) {
                            out[a].push(b);
                        }
                    }
                }
            }
        }
    }
    out
}

/// True when two convex polygons overlap by more than `eps` across every separating axis
/// candidate (their edge normals).
fn convex_overlap_2d(a: &[DVec2], b: &[DVec2], eps: f64) -> bool {
    for poly in [a, b] {
        for k in 0..poly.len() {
            let e = poly[(k + 1) % poly.len()] - poly[k];
            let axis = DVec2::new(-e.y, e.x);
            let len = axis.length();
            if len <= 0.0 {
                continue;
            }
            let axis = axis / len;
            let span = |p: &[DVec2]| p.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(axis.dot(*v)), hi.max(axis.dot(*v))));
            let (a0, a1) = span(a);
            let (b0, b1) = span(b);
            if a1 <= b0 + eps || b1 <= a0 + eps {
                return false;
            }
        }
    }
    true
}

