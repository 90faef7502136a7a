//! Occluders for exact shadows: coplanar, edge-connected input polygons merged into
//! larger convex polygons that block exactly the same set of segments.
//!
//! A building wall given as 216 one-metre facets casts one shadow, but the adaptive
//! method ([`super::adaptive`]) clips and cuts out every facet's shadow separately — and
//! the cuts along the facets' shared edges leave the receiver in slivers that every later
//! cut multiplies. Merging first changes nothing in the result (the union of the facets
//! is the same closed set, up to the edges between them, which have no area) and divides
//! the work by the number of facets per face.
//!
//! Two convex polygons in one plane, wound the same way, that share a whole edge (the
//! same two vertices, in opposite order) merge when their union is convex: the turns at
//! both ends of the shared edge stay left (or straight). Merging repeats until nothing
//! changes; collinear vertices are dropped, so a row of squares becomes one long
//! rectangle whose long edges then match the next row's. A regular grid of facets
//! becomes one rectangle per flat face; anything else merges as far as convexity allows.

use std::collections::HashMap;

use glam::DVec3;

/// Convex occluding polygons and, for each, the largest planarity tolerance of the
/// polygons it was merged from.
pub(crate) struct Occluders {
    pub verts: Vec<Vec<DVec3>>,
    pub normal: Vec<DVec3>,
    pub flat: Vec<f64>,
    pub bounds: Vec<(DVec3, DVec3)>,
    /// Whether its vertices lie within `eps` of its plane (else it is one input polygon,
    /// warped within the planarity tolerance `flat`).
    pub planar: Vec<bool>,
}

type Key = [u64; 3];

fn key(p: DVec3) -> Key {
    // +0.0 and −0.0 are one point.
    [(p.x + 0.0).to_bits(), (p.y + 0.0).to_bits(), (p.z + 0.0).to_bits()]
}

impl Occluders {
    /// Merges `polys` (convex, counter-clockwise about `normals`), whose planarity
    /// tolerances are `flat`. Polygons are merged only when each lies in the other's
    /// plane within `eps` and their normals agree to 1e-9; vertices are matched exactly.
    /// Also returns, per input polygon, the occluder it became part of.
    pub fn merge(polys: &[&[DVec3]], normals: &[DVec3], flat: &[f64], eps: f64) -> (Occluders, Vec<u32>) {
        let n = polys.len();
        let mut verts: Vec<Option<Vec<DVec3>>> = polys.iter().map(|p| Some(p.to_vec())).collect();
        let mut tol: Vec<f64> = flat.to_vec();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        // Each polygon's own deviation from its plane: only flat ones merge.
        let planar: Vec<bool> = (0..n)
            .map(|k| {
                let (o, nk) = (polys[k][0], normals[k]);
                polys[k].iter().all(|v| nk.dot(*v - o).abs() <= eps)
            })
            .collect();
        // Directed edge (a, b) → polygon holding it.
        let mut edges: HashMap<(Key, Key), u32> = HashMap::new();
        for (k, p) in polys.iter().enumerate() {
            if !planar[k] {
                continue;
            }
            for e in 0..p.len() {
                edges.insert((key(p[e]), key(p[(e + 1) % p.len()])), k as u32);
            }
        }
        let mut changed = true;
        while changed {
            changed = false;
            for k in 0..n {
                if !planar[k] {
                    continue;
                }
                loop {
                    let Some((q, u)) = verts[k].as_ref().and_then(|p| {
                        (0..p.len()).find_map(|e| {
                            let (a, b) = (p[e], p[(e + 1) % p.len()]);
                            let q = *edges.get(&(key(b), key(a)))? as usize;
                            let other = verts.get(q)?.as_ref()?;
                            let (nk, nq) = (normals[k], normals[q]);
                            if q == k || !planar[q] || nk.dot(nq) < 1.0 - 1e-9 {
                                return None;
                            }
                            if other.iter().any(|v| nk.dot(*v - p[0]).abs() > eps) || p.iter().any(|v| nq.dot(*v - other[0]).abs() > eps) {
                                return None;
                            }
                            union(p, e, other, nk, eps).map(|u| (q, u))
                        })
                    }) else {
                        break;
                    };
                    for poly in [verts[k].take().unwrap(), verts[q].take().unwrap()] {
                        for f in 0..poly.len() {
                            edges.remove(&(key(poly[f]), key(poly[(f + 1) % poly.len()])));
                        }
                    }
                    for f in 0..u.len() {
                        edges.insert((key(u[f]), key(u[(f + 1) % u.len()])), k as u32);
                    }
                    tol[k] = tol[k].max(tol[q]);
                    parent[q] = k as u32;
                    verts[k] = Some(u);
                    changed = true;
                }
            }
        }
        let mut out = Occluders { verts: Vec::new(), normal: Vec::new(), flat: Vec::new(), bounds: Vec::new(), planar: Vec::new() };
        let mut index = vec![u32::MAX; n];
        for (k, (v, t)) in verts.into_iter().zip(tol).enumerate() {
            if let Some(v) = v {
                index[k] = out.verts.len() as u32;
                out.bounds.push(crate::geom::bounds_3d(&v));
                out.verts.push(v);
                out.normal.push(normals[k]);
                out.planar.push(planar[k]);
                out.flat.push(t);
            }
        }
        // Follow each polygon's chain of merges to the survivor (each merge points the
        // absorbed polygon at the one that absorbed it, which survives or was absorbed
        // later).
        let of = (0..n)
            .map(|mut k| {
                while index[k] == u32::MAX {
                    k = parent[k] as usize;
                }
                index[k]
            })
            .collect();
        (out, of)
    }

    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.verts.len()
    }

    /// Is every segment between convex `a` and convex `b` blocked by occluder `o` alone?
    /// When `o`'s plane strictly separates them, the points where those segments cross
    /// it fill the convex hull of `a ∪ b` cut by the plane, which is the convex hull of
    /// the crossings of the segments between their vertices: all of those inside `o`
    /// means all of it is. (`tol` is the margin for "strictly".)
    pub fn hides(&self, o: usize, a: &[DVec3], b: &[DVec3], tol: f64) -> bool {
        let (v, n) = (&self.verts[o], self.normal[o]);
        let d = n.dot(v[0]);
        let side = |p: &DVec3| n.dot(*p) - d;
        let sa = side(&a[0]);
        if sa.abs() <= tol || a.iter().any(|p| side(p) * sa.signum() <= tol) || b.iter().any(|p| side(p) * sa.signum() >= -tol) {
            return false;
        }
        let m = v.len();
        let inside = |z: DVec3| {
            (0..m).all(|k| {
                let e = v[(k + 1) % m] - v[k];
                e.cross(z - v[k]).dot(n) >= -1e-12 * e.length_squared()
            })
        };
        a.iter().all(|p| {
            let dp = side(p);
            b.iter().all(|q| {
                let dq = side(q);
                inside(*p + (*q - *p) * (dp / (dp - dq)))
            })
        })
    }
}

/// The union of convex `p` and `q` across `p`'s edge `e` (which `q` holds reversed), if
/// it is convex; collinear vertices dropped.
fn union(p: &[DVec3], e: usize, q: &[DVec3], n: DVec3, eps: f64) -> Option<Vec<DVec3>> {
    let (a, b) = (p[e], p[(e + 1) % p.len()]);
    let kb = key(b);
    let jq = q.iter().position(|v| key(*v) == kb)?;
    // q runs b → a at jq; its other vertices follow a.
    if key(q[(jq + 1) % q.len()]) != key(a) {
        return None;
    }
    let mut u: Vec<DVec3> = Vec::with_capacity(p.len() + q.len() - 2);
    // p from b round to a, then q from after a round to before b.
    for s in 0..p.len() {
        u.push(p[(e + 1 + s) % p.len()]);
    }
    for s in 2..q.len() {
        u.push(q[(jq + s) % q.len()]);
    }
    // Convex: every turn left or straight (relative to the edges' lengths).
    let m = u.len();
    let mut keep = vec![true; m];
    for i in 0..m {
        let (prev, cur, next) = (u[(i + m - 1) % m], u[i], u[(i + 1) % m]);
        let (d0, d1) = (cur - prev, next - cur);
        let turn = d0.cross(d1).dot(n);
        let scale = d0.length() * d1.length();
        if turn < -1e-12 * scale - eps * (d0.length() + d1.length()) {
            return None;
        }
        if turn.abs() <= 1e-12 * scale && d0.dot(d1) > 0.0 {
            keep[i] = false;
        }
    }
    let u: Vec<DVec3> = u.into_iter().zip(keep).filter_map(|(v, k)| k.then_some(v)).collect();
    (u.len() >= 3).then_some(u)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize) -> Vec<Vec<DVec3>> {
        let mut out = Vec::new();
        for y in 0..ny {
            for x in 0..nx {
                let (x, y) = (x as f64, y as f64);
                out.push(vec![DVec3::new(x, y, 0.0), DVec3::new(x + 1.0, y, 0.0), DVec3::new(x + 1.0, y + 1.0, 0.0), DVec3::new(x, y + 1.0, 0.0)]);
            }
        }
        out
    }

    fn area(v: &[DVec3]) -> f64 {
        crate::geom::area_3d(v)
    }

    #[test]
    fn a_grid_of_squares_becomes_one_rectangle() {
        let g = grid(12, 18);
        let refs: Vec<&[DVec3]> = g.iter().map(|v| v.as_slice()).collect();
        let normals = vec![DVec3::Z; g.len()];
        let (o, _) = Occluders::merge(&refs, &normals, &vec![0.0; g.len()], 1e-9);
        assert_eq!(o.len(), 1);
        assert_eq!(o.verts[0].len(), 4);
        assert!((area(&o.verts[0]) - 216.0).abs() < 1e-9);
    }

    #[test]
    fn an_l_shape_stays_convex_pieces_of_the_same_area() {
        let mut g = grid(3, 3);
        g.remove(8); // the top-right square
        let refs: Vec<&[DVec3]> = g.iter().map(|v| v.as_slice()).collect();
        let normals = vec![DVec3::Z; g.len()];
        let (o, _) = Occluders::merge(&refs, &normals, &vec![0.0; g.len()], 1e-9);
        assert!(o.len() >= 2 && o.len() < 8, "{}", o.len());
        let total: f64 = o.verts.iter().map(|v| area(v)).sum();
        assert!((total - 8.0).abs() < 1e-9);
        // Every piece convex.
        for v in &o.verts {
            let m = v.len();
            for i in 0..m {
                let t = (v[i] - v[(i + m - 1) % m]).cross(v[(i + 1) % m] - v[i]).z;
                assert!(t > 0.0, "{v:?}");
            }
        }
    }

    #[test]
    fn opposite_sides_and_other_planes_do_not_merge() {
        let a = grid(1, 1).remove(0);
        let mut b: Vec<DVec3> = a.iter().map(|v| *v + DVec3::X).collect();
        // b reversed: the other side.
        b.reverse();
        let c: Vec<DVec3> = a.iter().map(|v| DVec3::new(v.x - 1.0, v.y, v.x * 0.5)).collect();
        let refs: Vec<&[DVec3]> = vec![&a, &b, &c];
        let normals = vec![DVec3::Z, -DVec3::Z, crate::geom::newell_normal(&c)];
        let (o, _) = Occluders::merge(&refs, &normals, &[0.0; 3], 1e-9);
        assert_eq!(o.len(), 3);
    }
}
