//! Primary visibility by rasterisation: a supersampled z-buffer of element ids and element
//! parameters.
//!
//! Every element is drawn as triangles (quads along the v0–v2 diagonal), clipped to the
//! near plane, projected, and scan-converted with edge functions over the samples whose
//! centres it covers; depth is compared as 1/z, which is affine in screen space for planar
//! triangles. Each sample keeps the visible element and its parameters there, interpolated
//! perspective-correctly: (u, v) of the bilinear map for quads (exact on parallelograms,
//! continuous across the diagonal otherwise) and the barycentric weights of v1, v2 for
//! triangles — so Gouraud shading needs no ray and no inverse map (the classic radiosity
//! display pipeline, Cohen & Greenberg 1985, without the hardware).

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::PinholeCamera;
use crate::mesh::Mesh;

/// Visible element per sample (`u32::MAX` = background) and its parameters, row-major,
/// `width × height`.
pub struct IdBuffer {
    /// Samples across.
    pub width: usize,
    /// Samples down.
    pub height: usize,
    /// Element ids.
    pub ids: Vec<u32>,
    /// Element parameters (u, v) at each sample.
    pub uv: Vec<[f32; 2]>,
}

struct ScreenTri {
    p: [DVec2; 3],
    inv_z: [f64; 3],
    /// Element parameters at the vertices, divided by z (for perspective-correct use).
    uv_z: [DVec2; 3],
    element: u32,
    ymin: usize,
    ymax: usize,
}

/// Rasterises the mesh seen by `cam` into a `width × height` sample grid (the camera must be
/// prepared for the same aspect). Sample (x, y) has its centre at (x + 0.5, y + 0.5).
/// Elements for which `two_sided(e)` is true are culled when seen from behind (their
/// coincident twin shows instead); back faces of one-sided elements are kept (they occlude
/// and render black).
pub fn rasterize(
    mesh: &Mesh,
    cam: &PinholeCamera,
    width: usize,
    height: usize,
    two_sided: &(dyn Fn(u32) -> bool + Sync),
) -> IdBuffer {
    let (right, up, fwd) = cam.frame();
    let (sx_scale, sy_scale) = cam.screen_scale();
    let (wf, hf) = (width as f64, height as f64);
    // Near plane: a tiny fraction of the scene's extent in front of the eye.
    let mut extent: f64 = 0.0;
    for p in &mesh.positions {
        extent = extent.max((*p - cam.eye).length());
    }
    let z_near = (extent * 1e-6).max(f64::MIN_POSITIVE);
    let screen: Vec<ScreenTri> = mesh
        .elements
        .par_iter()
        .enumerate()
        .flat_map_iter(|(e, el)| {
            let mut out = Vec::new();
            if two_sided(e as u32) && el.normal.dot(el.centroid - cam.eye) > 0.0 {
                return out;
            }
            let (c, n) = el.corners(&mesh.positions);
            // (triangle corners, their element parameters)
            let tris: [([usize; 3], [DVec2; 3]); 2] = if n == 4 {
                [
                    ([0, 1, 2], [DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(1.0, 1.0)]),
                    ([0, 2, 3], [DVec2::new(0.0, 0.0), DVec2::new(1.0, 1.0), DVec2::new(0.0, 1.0)]),
                ]
            } else {
                [([0, 1, 2], [DVec2::ZERO, DVec2::X, DVec2::Y]); 2]
            };
            for (ti, (idx, uvs)) in tris.iter().enumerate() {
                if n == 3 && ti == 1 {
                    break;
                }
                let cs: [DVec3; 3] = idx.map(|k| {
                    let d = c[k] - cam.eye;
                    DVec3::new(d.dot(right), d.dot(up), d.dot(fwd))
                });
                // Clip against z >= z_near (Sutherland–Hodgman); at most 4 vertices remain.
                let mut poly: Vec<(DVec3, DVec2)> = Vec::with_capacity(4);
                for k in 0..3 {
                    let (a, b) = (cs[k], cs[(k + 1) % 3]);
                    let (ua, ub) = (uvs[k], uvs[(k + 1) % 3]);
                    let (ina, inb) = (a.z >= z_near, b.z >= z_near);
                    if ina {
                        poly.push((a, ua));
                    }
                    if ina != inb {
                        let t = (z_near - a.z) / (b.z - a.z);
                        poly.push((a + (b - a) * t, ua + (ub - ua) * t));
                    }
                }
                if poly.len() < 3 {
                    continue;
                }
                let pr: Vec<(DVec2, f64, DVec2)> = poly
                    .iter()
                    .map(|(q, uv)| {
                        let iz = 1.0 / q.z;
                        let x = (q.x * iz * sx_scale + 1.0) * 0.5 * wf;
                        let y = (1.0 - q.y * iz * sy_scale) * 0.5 * hf;
                        (DVec2::new(x, y), iz, *uv * iz)
                    })
                    .collect();
                for k in 1..pr.len() - 1 {
                    let v = [pr[0], pr[k], pr[k + 1]];
                    let ymin = v.iter().map(|q| q.0.y).fold(f64::INFINITY, f64::min);
                    let ymax = v.iter().map(|q| q.0.y).fold(f64::NEG_INFINITY, f64::max);
                    if ymax < 0.0 || ymin > hf || !ymin.is_finite() || !ymax.is_finite() {
                        continue;
                    }
                    out.push(ScreenTri {
                        p: [v[0].0, v[1].0, v[2].0],
                        inv_z: [v[0].1, v[1].1, v[2].1],
                        uv_z: [v[0].2, v[1].2, v[2].2],
                        element: e as u32,
                        ymin: ymin.max(0.0).floor() as usize,
                        ymax: (ymax.ceil() as usize).min(height),
                    });
                }
            }
            out
        })
        .collect();

    // Bands of rows, rasterised in parallel; each band scans the triangles overlapping it.
    let band = 16usize;
    let nb = height.div_ceil(band);
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); nb];
    for (k, t) in screen.iter().enumerate() {
        if t.ymax <= t.ymin {
            continue;
        }
        for b in (t.ymin / band)..=((t.ymax - 1) / band).min(nb - 1) {
            bins[b].push(k as u32);
        }
    }
    let mut ids = vec![u32::MAX; width * height];
    let mut uv = vec![[0f32; 2]; width * height];
    ids.par_chunks_mut(width * band).zip(uv.par_chunks_mut(width * band)).enumerate().for_each(|(b, (chunk, uvc))| {
        let y0 = b * band;
        let rows = chunk.len() / width;
        let mut depth = vec![0.0f64; chunk.len()];
        let mut bary = vec![[0f64; 3]; chunk.len()];
        let mut owner = vec![u32::MAX; chunk.len()];
        for &k in &bins[b] {
            let t = &screen[k as usize];
            let [a, bb, c] = t.p;
            let area = (bb - a).perp_dot(c - a);
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            let inv_area = 1.0 / area;
            let xmin = a.x.min(bb.x).min(c.x).max(0.0).floor() as usize;
            let xmax = (a.x.max(bb.x).max(c.x).ceil().max(0.0) as usize).min(width);
            let ys = t.ymin.max(y0);
            let ye = t.ymax.min(y0 + rows);
            for y in ys..ye {
                let py = y as f64 + 0.5;
                for x in xmin..xmax {
                    let p = DVec2::new(x as f64 + 0.5, py);
                    let w0 = (bb - p).perp_dot(c - p) * inv_area;
                    let w1 = (c - p).perp_dot(a - p) * inv_area;
                    let w2 = 1.0 - w0 - w1;
                    if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                        continue;
                    }
                    let iz = w0 * t.inv_z[0] + w1 * t.inv_z[1] + w2 * t.inv_z[2];
                    let idx = (y - y0) * width + x;
                    if iz > depth[idx] {
                        depth[idx] = iz;
                        chunk[idx] = t.element;
                        owner[idx] = k;
                        bary[idx] = [w0, w1, w2];
                    }
                }
            }
        }
        // Parameters of the winning triangle only (perspective-correct).
        for idx in 0..chunk.len() {
            let k = owner[idx];
            if k == u32::MAX {
                continue;
            }
            let t = &screen[k as usize];
            let [w0, w1, w2] = bary[idx];
            let iz = w0 * t.inv_z[0] + w1 * t.inv_z[1] + w2 * t.inv_z[2];
            let q = (t.uv_z[0] * w0 + t.uv_z[1] * w1 + t.uv_z[2] * w2) / iz;
            uvc[idx] = [q.x as f32, q.y as f32];
        }
    });
    IdBuffer { width, height, ids, uv }
}
