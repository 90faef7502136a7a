//! Uniform subdivision of every patch to a target element size.
//!
//! Quadrilaterals become `nu × nv` grids and triangles the k² similar triangles of a
//! structured grid, so neighbouring elements of one patch share vertices. Polygons with more
//! than four vertices are cut as a fan with a common k, unless that fan would be slivers
//! (a many-sided disk): those are meshed by Delaunay refinement (Ruppert 1995; Chew 1993)
//! in their plane, with `spade`.

use std::collections::HashMap;

use glam::DVec3;

use super::{Element, Mesh, PatchElements, NO_VERTEX};
use crate::scene::{polygon_centroid, Scene};
use crate::{Error, Progress, Result};

/// Number of elements [`mesh_uniform`] would create (without creating them), saturating.
pub fn count_uniform(scene: &Scene, size: f64) -> u64 {
    let size = if size.is_finite() && size > 0.0 { size } else { f64::INFINITY };
    let steps = |len: f64| -> u64 { ((len / size).ceil()).clamp(1.0, 1e9) as u64 };
    let mut total: u64 = 0;
    for poly in &scene.polygons {
        let v = &poly.vertices;
        let n = if v.len() == 4 {
            let nu = steps((v[1] - v[0]).length().max((v[2] - v[3]).length()));
            let nv = steps((v[3] - v[0]).length().max((v[2] - v[1]).length()));
            nu.saturating_mul(nv)
        } else {
            match plan(poly, size) {
                Plan::Fan(k) => (k as u64).saturating_mul(k as u64).saturating_mul(v.len() as u64 - 2),
                Plan::Delaunay(estimate) => estimate,
            }
        };
        total = total.saturating_add(n);
    }
    total
}

/// Subdivides every polygon of `scene` into elements no larger than `size` (scene units)
/// along any edge of a quadrilateral, and no longer than `size·√2` (the diagonal of a
/// `size × size` square) along any edge of a triangle: a right triangle cut to `size` along
/// its hypotenuse would get four times the elements of the square it is half of.
/// `size <= 0` or non-finite leaves each polygon whole (one element per triangle/quad, fans
/// for larger polygons).
pub fn mesh_uniform(scene: &Scene, size: f64) -> Mesh {
    mesh_uniform_with(scene, size, &crate::NoProgress).expect("NoProgress never stops")
}

/// [`mesh_uniform`] reporting one unit of progress per polygon ("mesh" stage) and polling
/// [`Progress::should_stop`] before every polygon: an interrupt ends meshing with
/// [`Error::Cancelled`] (a partial mesh is of no use).
pub fn mesh_uniform_with(scene: &Scene, size: f64, progress: &dyn Progress) -> Result<Mesh> {
    let size = if size.is_finite() && size > 0.0 { size } else { f64::INFINITY };
    let mut mesh = Mesh { target_size: size, ..Default::default() };
    progress.begin("mesh", scene.polygons.len() as u64);
    for (pi, poly) in scene.polygons.iter().enumerate() {
        if progress.should_stop() {
            progress.end();
            return Err(Error::Cancelled);
        }
        let first = mesh.elements.len() as u32;
        let mut b = PatchBuilder { mesh: &mut mesh, patch: pi as u32, normal: poly.normal, map: HashMap::new() };
        let v = &poly.vertices;
        let steps = |len: f64| -> usize { ((len / size).ceil() as usize).clamp(1, 100_000) };
        if v.len() == 4 {
            let nu = steps((v[1] - v[0]).length().max((v[2] - v[3]).length()));
            let nv = steps((v[3] - v[0]).length().max((v[2] - v[1]).length()));
            let p = |i: usize, j: usize| {
                let (u, t) = (i as f64 / nu as f64, j as f64 / nv as f64);
                v[0].lerp(v[1], u).lerp(v[3].lerp(v[2], u), t)
            };
            for j in 0..nv {
                for i in 0..nu {
                    b.push(&[p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
                }
            }
        } else {
            match plan(poly, size) {
                // Many-sided polygon (a disk, a rounded outline): refined Delaunay
                // triangles, or the fan if the refinement runs out of its vertex budget.
                Plan::Delaunay(estimate) if delaunay(&mut b, v, poly.normal, size, estimate) => {}
                Plan::Delaunay(_) => fan(&mut b, v, fan_steps(v, size)),
                Plan::Fan(k) => fan(&mut b, v, k),
            }
        }
        let count = mesh.elements.len() as u32 - first;
        mesh.patches.push(PatchElements { first, count });
        progress.advance(1);
    }
    progress.end();
    Ok(mesh)
}

/// Fan triangles from `v[0]` (a triangle is its own fan), each cut into k² triangles with a
/// common k, so the fan edges conform.
fn fan(b: &mut PatchBuilder, v: &[DVec3], k: usize) {
    for f in 1..v.len() - 1 {
        let (a, e1, e2) = (v[0], v[f] - v[0], v[f + 1] - v[0]);
        let p = |i: usize, j: usize| a + e1 * (i as f64 / k as f64) + e2 * (j as f64 / k as f64);
        for j in 0..k {
            for i in 0..k - j {
                b.push(&[p(i, j), p(i + 1, j), p(i, j + 1)]);
                if i + j + 1 < k {
                    b.push(&[p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
                }
            }
        }
    }
}

/// The common subdivision count of a polygon's fan triangles: a quad element's longest
/// extent is its diagonal, size·√2, and triangle elements get the same.
fn fan_steps(v: &[DVec3], size: f64) -> usize {
    let mut longest: f64 = 0.0;
    for k in 1..v.len() - 1 {
        let (a, b, c) = (v[0], v[k], v[k + 1]);
        longest = longest.max((b - a).length()).max((c - b).length()).max((a - c).length());
    }
    ((longest / std::f64::consts::SQRT_2 / size).ceil()).clamp(1.0, 100_000.0) as usize
}

/// How a polygon other than a quad is cut.
enum Plan {
    /// Fan triangles, each into k² triangles.
    Fan(usize),
    /// Refined Delaunay triangles, about this many.
    Delaunay(u64),
}

/// Polygons with more than four vertices whose fan would be made of slivers (a 256-gon
/// disk: every fan triangle spans the diameter and is cut into k² thinner slivers, ~80×
/// the elements its area needs) are meshed by constrained Delaunay refinement instead
/// (Ruppert/Chew, the `spade` crate): triangles of area ≤ size²/2 (half a size × size
/// square, as the fan's) and no angle below 20° except at input corners; expected count
/// 1.5 × 2·area/size² plus two per boundary vertex.
fn plan(poly: &crate::scene::Polygon, size: f64) -> Plan {
    let v = &poly.vertices;
    let k = fan_steps(v, size);
    if v.len() <= 4 || !size.is_finite() {
        return Plan::Fan(k);
    }
    let ideal = 2.0 * poly.area / (size * size);
    if !ideal.is_finite() || ideal < 1.0 {
        return Plan::Fan(k);
    }
    let estimate = (1.5 * ideal).ceil() as u64 + 2 * v.len() as u64;
    let fan = (k as u64).saturating_mul(k as u64).saturating_mul(v.len() as u64 - 2);
    if fan > 3 * estimate {
        Plan::Delaunay(estimate)
    } else {
        Plan::Fan(k)
    }
}

/// Meshes the convex planar polygon `v` by refined constrained Delaunay triangulation in
/// its plane; false (nothing pushed) if the refinement cannot finish within its vertex
/// budget, so the caller falls back to the fan.
fn delaunay(b: &mut PatchBuilder, v: &[DVec3], normal: DVec3, size: f64, estimate: u64) -> bool {
    use spade::{AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation};
    let n = normal.normalize();
    let u = n.any_orthonormal_vector();
    let w = n.cross(u); // u × w = n: counter-clockwise in (u, w) is the polygon's front
    let o = v[0];
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> = ConstrainedDelaunayTriangulation::new();
    let mut handles = Vec::with_capacity(v.len());
    for p in v {
        let d = *p - o;
        match cdt.insert(Point2::new(d.dot(u), d.dot(w))) {
            Ok(h) => handles.push(h),
            Err(_) => return false,
        }
    }
    for k in 0..handles.len() {
        let (a, c) = (handles[k], handles[(k + 1) % handles.len()]);
        if a != c && cdt.can_add_constraint(a, c) {
            cdt.add_constraint(a, c);
        }
    }
    let params = RefinementParameters::<f64>::new()
        .with_max_allowed_area(0.5 * size * size)
        .with_angle_limit(AngleLimit::from_deg(20.0))
        .exclude_outer_faces(true)
        .with_max_additional_vertices(10 * estimate as usize);
    let result = cdt.refine(params);
    if !result.refinement_complete {
        return false;
    }
    let excluded: std::collections::HashSet<_> = result.excluded_faces.into_iter().collect();
    // Input corners keep their exact positions; Steiner points come back from the plane.
    let mut input = std::collections::HashMap::new();
    for (k, h) in handles.iter().enumerate() {
        input.entry(h.index()).or_insert(v[k]);
    }
    let pos = |vh: spade::handles::VertexHandle<Point2<f64>, (), spade::CdtEdge<()>, ()>| -> DVec3 {
        if let Some(p) = input.get(&vh.fix().index()) {
            return *p;
        }
        let q = vh.position();
        o + u * q.x + w * q.y
    };
    for f in cdt.inner_faces() {
        if excluded.contains(&f.fix()) {
            continue;
        }
        let [a, c, d] = f.vertices();
        b.push(&[pos(a), pos(c), pos(d)]);
    }
    true
}

struct PatchBuilder<'a> {
    mesh: &'a mut Mesh,
    patch: u32,
    normal: DVec3,
    map: HashMap<[u64; 3], u32>,
}

impl PatchBuilder<'_> {
    fn vertex(&mut self, p: DVec3) -> u32 {
        // Grid points of one patch are computed by the same formula from the same corners,
        // so coincident points are bit-identical except along fan edges; round lightly.
        let key = [round_key(p.x), round_key(p.y), round_key(p.z)];
        let positions = &mut self.mesh.positions;
        *self.map.entry(key).or_insert_with(|| {
            positions.push(p);
            (positions.len() - 1) as u32
        })
    }

    fn push(&mut self, corners: &[DVec3]) {
        let area = 0.5 * crate::scene::newell_normal(corners).length();
        if !(area > 0.0) {
            return;
        }
        let mut vs = [NO_VERTEX; 4];
        for (k, c) in corners.iter().enumerate() {
            vs[k] = self.vertex(*c);
        }
        self.mesh.elements.push(Element {
            vertices: vs,
            patch: self.patch,
            area,
            centroid: polygon_centroid(corners),
            normal: self.normal,
        });
    }
}

/// Rounds to ~40 significant bits so that points equal up to rounding share a key.
pub(super) fn round_key(x: f64) -> u64 {
    let b = (x + 0.0).to_bits(); // +0.0 folds -0.0 into 0.0
    (b + (1 << 11)) >> 12
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{builtin, Scene};

    #[test]
    fn subdivision_preserves_area_and_shares_vertices() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let mesh = mesh_uniform(&scene, 50.0);
        for (pi, p) in scene.polygons.iter().enumerate() {
            let pe = mesh.patches[pi];
            let a: f64 = mesh.elements[pe.first as usize..(pe.first + pe.count) as usize].iter().map(|e| e.area).sum();
            assert!((a - p.area).abs() < 1e-9 * p.area, "patch {pi}: {a} vs {}", p.area);
        }
        // A quad cut into nu x nv has (nu+1)(nv+1) vertices, far fewer than 4 per element.
        assert!(mesh.positions.len() < 2 * mesh.elements.len());
        let floor = mesh.patches[0];
        assert_eq!(floor.count, 12 * 12);
    }

    #[test]
    fn parameters_invert_point_on_triangles_and_non_parallelogram_quads() {
        let positions = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.5, 1.2, 0.0),
            DVec3::new(-0.3, 0.9, 0.0),
        ];
        let quad = super::super::Element { vertices: [0, 1, 2, 3], patch: 0, area: 1.0, centroid: DVec3::ZERO, normal: DVec3::Z };
        let tri = super::super::Element { vertices: [0, 1, 2, NO_VERTEX], ..quad };
        for e in [quad, tri] {
            for (u, v) in [(0.1, 0.2), (0.5, 0.5), (0.93, 0.07), (0.3, 0.99)] {
                let x = e.point(&positions, u, v);
                let (pu, pv) = e.parameters(&positions, x);
                assert!((pu - u).abs() < 1e-9 && (pv - v).abs() < 1e-9, "{:?}: ({u}, {v}) came back as ({pu}, {pv})", e.vertices);
            }
        }
    }

    #[test]
    fn open_cells_are_found_where_they_lie() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let mesh = mesh_uniform(&scene, 200.0);
        let mut r = crate::mesh::Receivers::all_open(&mesh);
        // Element 0: only the cells with i < 4 (u < 1/2) and j = 7 (v ≥ 7/8) open.
        r.open_cells[0] = (0..4).map(|i| 1u64 << (7 * 8 + i)).sum();
        assert!(r.open_at(0, 0.1, 0.9) && r.open_at(0, 0.49, 0.999));
        assert!(!r.open_at(0, 0.51, 0.9) && !r.open_at(0, 0.1, 0.8));
        assert!(r.open_at(1, 0.7, 0.2), "an element with no covered cell is open everywhere");
        for k in 0..4 {
            assert_eq!(r.open_cell(0, k), Some((k as f64 / 8.0, 7.0 / 8.0)));
        }
        r.open_cells[0] = 0;
        assert_eq!(r.open_cell(0, 0), None);
    }

    #[test]
    fn open_pieces_cover_exactly_the_open_cells_of_quads_and_triangles() {
        let positions = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.5, 1.2, 0.0),
            DVec3::new(-0.3, 0.9, 0.0),
        ];
        let quad = Element { vertices: [0, 1, 2, 3], patch: 0, area: 0.0, centroid: DVec3::ZERO, normal: DVec3::Z };
        let tri = Element { vertices: [0, 1, 2, NO_VERTEX], ..quad };
        let area = |p: &[DVec3]| (1..p.len() - 1).map(|k| (p[k] - p[0]).cross(p[k + 1] - p[0]).z).sum::<f64>() / 2.0;
        for mut e in [quad, tri] {
            let (c, n) = e.corners(&positions);
            e.area = area(&c[..n]);
            let mesh = Mesh { positions: positions.clone(), elements: vec![e], patches: vec![PatchElements { first: 0, count: 1 }], ..Default::default() };
            let mut r = crate::mesh::Receivers::all_open(&mesh);
            for mask in [0x00fe_0000_00e0_e0c0u64, 0xd1d1_d1d1_d1d1_d151, 0x3f3f_ffff_ffff_ffff, 1, u64::MAX] {
                r.open_cells[0] = mask;
                let pieces = r.open_pieces(&mesh, 0);
                let sum: f64 = pieces.iter().map(|p| area(p)).sum();
                let cell = |b: u32| {
                    let (u, v) = ((b % 8) as f64 / 8.0, (b / 8) as f64 / 8.0);
                    let c: Vec<DVec3> = [(u, v), (u + 0.125, v), (u + 0.125, v + 0.125), (u, v + 0.125)].iter().map(|&(a, b)| e.point(&positions, a, b)).collect();
                    area(&c)
                };
                let want: f64 = (0..64).filter(|b| mask >> b & 1 == 1).map(cell).sum();
                assert!((sum - want).abs() < 1e-12, "{:?} mask {mask:016x}: pieces {sum}, open area {want}", e.vertices);
                assert!(pieces.iter().all(|p| area(p) > 0.0), "a piece is wound clockwise");
                // Every open cell's centre lies in one piece, every covered one in none.
                for b in 0..64 {
                    let x = e.point(&positions, ((b % 8) as f64 + 0.5) / 8.0, ((b / 8) as f64 + 0.5) / 8.0);
                    let inside = pieces.iter().filter(|p| crate::geom::inside_convex(x, p, DVec3::Z, 0.0)).count();
                    assert_eq!(inside, (mask >> b & 1) as usize, "cell {b} of mask {mask:016x}");
                }
            }
        }
    }

    /// Stops once `after` units of progress were reported; counts them.
    struct StopAfter {
        after: u64,
        done: std::sync::atomic::AtomicU64,
    }
    impl Progress for StopAfter {
        fn advance(&self, n: u64) {
            self.done.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        }
        fn should_stop(&self) -> bool {
            self.done.load(std::sync::atomic::Ordering::Relaxed) >= self.after
        }
    }

    #[test]
    fn meshing_interrupt_stops_after_the_polygon_in_progress() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        let stop = StopAfter { after: 3, done: Default::default() };
        let r = mesh_uniform_with(&scene, 5.0, &stop);
        assert!(matches!(r, Err(Error::Cancelled)), "meshing went on after the interrupt");
        assert_eq!(stop.done.load(std::sync::atomic::Ordering::Relaxed), 3, "polygons meshed after the stop");
        // Without an interrupt: every polygon, and the same mesh as mesh_uniform.
        let all = StopAfter { after: u64::MAX, done: Default::default() };
        let m = mesh_uniform_with(&scene, 50.0, &all).unwrap();
        assert_eq!(all.done.load(std::sync::atomic::Ordering::Relaxed), scene.polygons.len() as u64);
        assert_eq!(m.elements, mesh_uniform(&scene, 50.0).elements);
    }

    #[test]
    fn triangle_subdivision_is_conforming() {
        let scene = Scene::from_desc(builtin::cornell()).unwrap();
        // The red wall is two triangles (non-planar input).
        let tri_patch = scene.polygons.iter().position(|p| p.vertices.len() == 3).unwrap();
        let mesh = mesh_uniform(&scene, 100.0);
        let pe = mesh.patches[tri_patch];
        let k = (scene.polygons[tri_patch].vertices.windows(2).map(|w| (w[1] - w[0]).length()).fold(0.0, f64::max)
            / (100.0 * std::f64::consts::SQRT_2))
            .ceil() as u32;
        assert!(pe.count >= k * k);
        for e in &mesh.elements[pe.first as usize..(pe.first + pe.count) as usize] {
            assert!(e.normal.dot(scene.polygons[tri_patch].normal) > 0.999999);
            assert_eq!(e.vertex_count(), 3);
        }
    }
    #[test]
    fn many_sided_polygons_get_compact_delaunay_triangles() {
        use crate::scene::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
        let n = 200;
        let disk: Vec<DVec3> = (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                DVec3::new(t.cos(), t.sin(), 0.0)
            })
            .collect();
        let desc = SceneDesc {
            materials: vec![MaterialDesc::diffuse("grey", crate::Rgb::splat(0.5))],
            objects: vec![ObjectDesc { name: "disk".into(), loc: None }],
            polygons: vec![PolygonDesc { uvs: Vec::new(), vertices: disk, material: 0, object: 0, loc: None }],
            ..Default::default()
        };
        let scene = Scene::from_desc(desc).unwrap();
        let size = 0.1;
        let mesh = mesh_uniform(&scene, size);
        let poly = &scene.polygons[0];
        let ideal = 2.0 * poly.area / (size * size); // triangles of half a size × size square
        let count = mesh.elements.len() as f64;
        assert!(count >= ideal && count <= 3.0 * ideal, "{count} elements, ideal {ideal}");
        let est = count_uniform(&scene, size) as f64;
        assert!(est >= 0.5 * count && est <= 2.0 * count, "estimate {est} vs {count}");
        let area: f64 = mesh.elements.iter().map(|e| e.area).sum();
        assert!((area - poly.area).abs() < 1e-9 * poly.area);
        for e in &mesh.elements {
            let (c, k) = e.corners(&mesh.positions);
            assert_eq!(k, 3);
            // Front side kept (counter-clockwise about the polygon's normal), no slivers.
            assert!((c[1] - c[0]).cross(c[2] - c[0]).dot(poly.normal) > 0.0);
            let longest = (c[1] - c[0]).length().max((c[2] - c[1]).length()).max((c[0] - c[2]).length());
            assert!(longest <= 2.0 * size, "element {longest} long");
        }
        // Vertices shared: a triangulation of V vertices has about 2V triangles.
        assert!((mesh.positions.len() as f64) < 0.7 * count + n as f64);
    }
    #[test]
    fn delaunay_meshing_keeps_the_area_of_random_convex_polygons() {
        use crate::scene::{MaterialDesc, ObjectDesc, PolygonDesc, SceneDesc};
        // Ellipses with uneven vertex spacing, some nearly collinear runs, at sizes from
        // a few elements to thousands; every one must keep its area (or fall back to the fan).
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut delaunay_cases = 0;
        for case in 0..40 {
            let n = 5 + (rnd() * 300.0) as usize;
            let (a, b) = (0.2 + 3.0 * rnd(), 0.2 + 3.0 * rnd());
            let mut ts: Vec<f64> = (0..n).map(|_| rnd() * std::f64::consts::TAU).collect();
            ts.sort_by(|x, y| x.partial_cmp(y).unwrap());
            ts.dedup_by(|x, y| (*x - *y).abs() < 1e-6);
            let poly: Vec<DVec3> = ts.iter().map(|t| DVec3::new(a * t.cos(), b * t.sin(), 0.5 * a * t.cos())).collect();
            let desc = SceneDesc {
                materials: vec![MaterialDesc::diffuse("grey", crate::Rgb::splat(0.5))],
                objects: vec![ObjectDesc { name: "p".into(), loc: None }],
                polygons: vec![PolygonDesc { uvs: Vec::new(), vertices: poly, material: 0, object: 0, loc: None }],
                ..Default::default()
            };
            let Ok(scene) = Scene::from_desc(desc) else { continue };
            let size = a.max(b) * (0.02 + 0.5 * rnd());
            let mesh = mesh_uniform(&scene, size);
            if matches!(plan(&scene.polygons[0], size), Plan::Delaunay(_)) {
                delaunay_cases += 1;
            }
            let want: f64 = scene.polygons.iter().map(|p| p.area).sum();
            let got: f64 = mesh.elements.iter().map(|e| e.area).sum();
            assert!((got - want).abs() <= 1e-9 * want, "case {case}: n {n}, size {size}: area {got} vs {want}");
            for e in &mesh.elements {
                assert!(e.area > 0.0 && e.centroid.is_finite());
            }
        }
        assert!(delaunay_cases >= 10, "only {delaunay_cases} cases took the Delaunay path");
    }
}
