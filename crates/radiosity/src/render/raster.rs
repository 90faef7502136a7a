//! Primary visibility by rasterisation: a supersampled z-buffer of element ids.
//!
//! Every element triangle is clipped to the near plane, projected, and scan-converted with
//! edge functions over the samples whose centres it covers; depth is compared as 1/z, which
//! is affine in screen space for planar triangles. The result is, per sample, the visible
//! element; the shading stage recovers the exact surface point by intersecting the
//! sample's camera ray with that element's plane, so the image is identical in geometry to
//! ray casting, at a fraction of the cost (the classic radiosity display pipeline,
//! Cohen & Greenberg 1985, without the hardware).

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::PinholeCamera;
use crate::mesh::Mesh;

/// Visible element per sample (`u32::MAX` = background), row-major, `width × height`.
pub struct IdBuffer {
    /// Samples across.
    pub width: usize,
    /// Samples down.
    pub height: usize,
    /// Element ids.
    pub ids: Vec<u32>,
}

struct ScreenTri {
    p: [DVec2; 3],
    inv_z: [f64; 3],
    element: u32,
    ymin: usize,
    ymax: usize,
}

/// Rasterises the mesh seen by `cam` into a `width × height` sample grid (the camera must be
/// prepared for the same size). Sample (x, y) has its centre at (x + 0.5, y + 0.5).
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
    let (tris, owner) = mesh.triangles();
    let project = |c: DVec3| -> (DVec2, f64) {
        let z = c.z;
        let x = (c.x / z * sx_scale + 1.0) * 0.5 * wf;
        let y = (1.0 - c.y / z * sy_scale) * 0.5 * hf;
        (DVec2::new(x, y), 1.0 / z)
    };
    let screen: Vec<ScreenTri> = tris
        .par_iter()
        .zip(owner.par_iter())
        .flat_map_iter(|(t, &e)| {
            let el = &mesh.elements[e as usize];
            if two_sided(e) && el.normal.dot(el.centroid - cam.eye) > 0.0 {
                return Vec::new();
            }
            let cs: Vec<DVec3> = t
                .iter()
                .map(|v| {
                    let d = v.as_dvec3() - cam.eye;
                    DVec3::new(d.dot(right), d.dot(up), d.dot(fwd))
                })
                .collect();
            // Clip against z >= z_near (Sutherland–Hodgman); at most 4 vertices remain.
            let mut poly: Vec<DVec3> = Vec::with_capacity(4);
            for k in 0..3 {
                let (a, b) = (cs[k], cs[(k + 1) % 3]);
                let (ina, inb) = (a.z >= z_near, b.z >= z_near);
                if ina {
                    poly.push(a);
                }
                if ina != inb {
                    let t = (z_near - a.z) / (b.z - a.z);
                    poly.push(a + (b - a) * t);
                }
            }
            let mut out = Vec::new();
            if poly.len() >= 3 {
                let pr: Vec<(DVec2, f64)> = poly.iter().map(|c| project(*c)).collect();
                for k in 1..pr.len() - 1 {
                    let p = [pr[0].0, pr[k].0, pr[k + 1].0];
                    let ymin = p.iter().map(|q| q.y).fold(f64::INFINITY, f64::min);
                    let ymax = p.iter().map(|q| q.y).fold(f64::NEG_INFINITY, f64::max);
                    if ymax < 0.0 || ymin > hf || !ymin.is_finite() || !ymax.is_finite() {
                        continue;
                    }
                    out.push(ScreenTri {
                        p,
                        inv_z: [pr[0].1, pr[k].1, pr[k + 1].1],
                        element: e,
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
        for b in (t.ymin / band)..=((t.ymax.saturating_sub(1)) / band).min(nb - 1) {
            bins[b].push(k as u32);
        }
    }
    let mut ids = vec![u32::MAX; width * height];
    ids.par_chunks_mut(width * band).enumerate().for_each(|(b, chunk)| {
        let y0 = b * band;
        let rows = chunk.len() / width;
        let mut depth = vec![0.0f64; chunk.len()];
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
                    }
                }
            }
        }
    });
    IdBuffer { width, height, ids }
}
