//! Gouraud rendering: per pixel, `spp × spp` primary rays find the visible element, whose
//! radiosity is interpolated from its vertices (bilinearly on quads through the inverse
//! bilinear map, barycentrically on triangles) — the classic radiosity display
//! (Cohen & Greenberg 1985). `Shading::Flat` shows the element constants instead.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::{Image, PinholeCamera};
use crate::accel::{Bvh, Ray};
use crate::mesh::Mesh;
use crate::{Progress, Rgb};

/// How element values are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shading {
    /// Interpolated from the vertices.
    Gouraud,
    /// One constant per element.
    Flat,
}

/// Image options.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Samples per pixel along each axis (box filter over the pixel).
    pub spp_axis: usize,
    /// Shading.
    pub shading: Shading,
}

/// Ray casting against the element triangles.
pub struct ElementTracer {
    bvh: Bvh,
    owner: Vec<u32>,
    /// Per element: (normal, one side of a two-sided pair).
    facing: Vec<(glam::Vec3, bool)>,
}

impl ElementTracer {
    /// Builds the BVH over the mesh's element triangles. `two_sided_patch[p]` marks patches
    /// that are one side of a two-sided pair (see [`crate::scene::Polygon::two_sided`]).
    pub fn new(mesh: &Mesh, two_sided_patch: &[bool]) -> Self {
        let (tris, owner) = mesh.triangles();
        let facing = mesh
            .elements
            .iter()
            .map(|e| (e.normal.as_vec3(), two_sided_patch.get(e.patch as usize).copied().unwrap_or(false)))
            .collect();
        ElementTracer { bvh: Bvh::build(&tris), owner, facing }
    }

    /// The element hit first by the ray and the hit point, if any. The back face of one side
    /// of a two-sided pair is skipped (its twin, at the same place, faces the ray).
    #[inline]
    pub fn trace(&self, origin: DVec3, dir: DVec3) -> Option<(u32, DVec3)> {
        let d = dir.as_vec3();
        let ray = Ray::new(origin.as_vec3(), d, 0.0, f32::INFINITY);
        let h = self.bvh.intersect_filtered(&ray, |prim| {
            let (n, two) = self.facing[self.owner[prim as usize] as usize];
            two && n.dot(d) > 0.0
        })?;
        let p = origin + dir * h.t as f64;
        Some((self.owner[h.prim as usize], p))
    }

    /// The underlying hierarchy.
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Element of a BVH primitive.
    pub fn owner(&self, prim: u32) -> u32 {
        self.owner[prim as usize]
    }
}

/// Radiosity at a point `p` on element `e`, interpolated from vertex values.
pub fn interpolate(mesh: &Mesh, e: u32, p: DVec3, vertex_b: &[Rgb]) -> Rgb {
    let el = &mesh.elements[e as usize];
    let (c, n) = el.corners(&mesh.positions);
    let vb = |k: usize| vertex_b[el.vertices[k] as usize];
    if n == 3 {
        let (w0, w1, w2) = barycentric(p, c[0], c[1], c[2]);
        vb(0) * w0 + vb(1) * w1 + vb(2) * w2
    } else {
        let (u, v) = inverse_bilinear(p, &c, el.normal);
        vb(0) * ((1.0 - u) * (1.0 - v)) + vb(1) * (u * (1.0 - v)) + vb(2) * (u * v) + vb(3) * ((1.0 - u) * v)
    }
}

/// Value at element parameters (u, v): bilinear on quads, barycentric (weights of v1, v2)
/// on triangles.
#[inline]
pub fn interpolate_uv(mesh: &Mesh, e: u32, u: f64, v: f64, vertex_b: &[Rgb]) -> Rgb {
    let el = &mesh.elements[e as usize];
    let vb = |k: usize| vertex_b[el.vertices[k] as usize];
    let (u, v) = (u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
    if el.vertices[3] == crate::mesh::NO_VERTEX {
        let w0 = (1.0 - u - v).max(0.0);
        vb(0) * w0 + vb(1) * u + vb(2) * v
    } else {
        vb(0) * ((1.0 - u) * (1.0 - v)) + vb(1) * (u * (1.0 - v)) + vb(2) * (u * v) + vb(3) * ((1.0 - u) * v)
    }
}

/// Barycentric weights of p in triangle (a, b, c), clamped to the triangle.
pub fn barycentric(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (f64, f64, f64) {
    let (v0, v1, v2) = (b - a, c - a, p - a);
    let (d00, d01, d11, d20, d21) = (v0.dot(v0), v0.dot(v1), v1.dot(v1), v2.dot(v0), v2.dot(v1));
    let den = d00 * d11 - d01 * d01;
    if den <= 0.0 {
        return (1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0);
    }
    let v = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
    let w = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - v);
    (1.0 - v - w, v, w)
}

/// (u, v) ∈ [0,1]² with p = lerp(lerp(c0,c1,u), lerp(c3,c2,u), v) for a planar quad
/// (after Quílez, "inverse bilinear interpolation").
pub fn inverse_bilinear(p: DVec3, c: &[DVec3; 4], normal: DVec3) -> (f64, f64) {
    let a = normal.abs();
    let (ix, iy) = if a.x >= a.y && a.x >= a.z {
        (1, 2)
    } else if a.y >= a.z {
        (2, 0)
    } else {
        (0, 1)
    };
    let to2 = |q: DVec3| DVec2::new(q[ix], q[iy]);
    let (pa, pb, pc, pd, pp) = (to2(c[0]), to2(c[1]), to2(c[2]), to2(c[3]), to2(p));
    let cross = |a: DVec2, b: DVec2| a.x * b.y - a.y * b.x;
    let e = pb - pa;
    let f = pd - pa;
    let g = pa - pb + pc - pd;
    let h = pp - pa;
    let k2 = cross(g, f);
    let k1 = cross(e, f) + cross(h, g);
    let k0 = cross(h, e);
    let solve_u = |v: f64| {
        let den = e + g * v;
        let num = h - f * v;
        if den.x.abs() > den.y.abs() {
            num.x / den.x
        } else {
            num.y / den.y
        }
    };
    let scale = cross(e, f).abs().max(f64::MIN_POSITIVE);
    let (u, v) = if k2.abs() <= 1e-9 * scale {
        let v = -k0 / k1;
        (solve_u(v), v)
    } else {
        let w = (k1 * k1 - 4.0 * k0 * k2).max(0.0).sqrt();
        let ik2 = 0.5 / k2;
        let mut v = (-k1 - w) * ik2;
        let mut u = solve_u(v);
        if !(-1e-6..=1.0 + 1e-6).contains(&u) || !(-1e-6..=1.0 + 1e-6).contains(&v) {
            v = (-k1 + w) * ik2;
            u = solve_u(v);
        }
        (u, v)
    };
    let fix = |t: f64| if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.5 };
    (fix(u), fix(v))
}

/// Renders the mesh with per-vertex radiosity `vertex_b` (Gouraud) or per-element
/// radiosity `element_b` (flat). Primary visibility comes from the rasteriser
/// ([`super::raster`]); each sample's surface point is its camera ray's intersection with
/// the visible element's plane. A sample that sees no element shows `background` of its
/// direction (the sky's radiance, or zero).
#[allow(clippy::too_many_arguments)]
pub fn render(
    mesh: &Mesh,
    tracer: &ElementTracer,
    element_b: &[Rgb],
    vertex_b: &[Rgb],
    cam: &PinholeCamera,
    opts: &Options,
    background: &(dyn Fn(glam::DVec3) -> Rgb + Sync),
    progress: &dyn Progress,
) -> Image {
    let (w, h) = (opts.width, opts.height);
    let s = opts.spp_axis.max(1);
    progress.begin("render", h as u64);
    let ids = super::raster::rasterize(mesh, cam, w * s, h * s, &|e| tracer.facing[e as usize].1);
    // Planar elements face the eye entirely or not at all.
    let front: Vec<bool> = mesh.elements.iter().map(|e| e.normal.dot(e.centroid - cam.eye) < 0.0).collect();
    let inv_spp = 1.0 / (s * s) as f64;
    let inv_pi = 1.0 / std::f64::consts::PI;
    let stopped = AtomicBool::new(false);
    let mut img = Image::new(w, h);
    img.pixels.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        if stopped.load(Ordering::Relaxed) || progress.should_stop() {
            stopped.store(true, Ordering::Relaxed);
            return;
        }
        for (x, px) in row.iter_mut().enumerate() {
            let mut acc = Rgb::ZERO;
            for sj in 0..s {
                for si in 0..s {
                    let k = (y * s + sj) * ids.width + x * s + si;
                    let e = ids.ids[k];
                    if e == u32::MAX {
                        let dir = cam.direction(x as f64 + (si as f64 + 0.5) / s as f64, y as f64 + (sj as f64 + 0.5) / s as f64);
                        acc += background(dir) * std::f64::consts::PI; // (divided by π below)
                        continue;
                    }
                    if !front[e as usize] {
                        continue; // the back of a one-sided surface: black
                    }
                    acc += match opts.shading {
                        Shading::Flat => element_b[e as usize],
                        Shading::Gouraud => {
                            let [u, v] = ids.uv[k];
                            interpolate_uv(mesh, e, u as f64, v as f64, vertex_b)
                        }
                    };
                }
            }
            *px = acc * (inv_spp * inv_pi);
        }
        progress.advance(1);
    });
    progress.end();
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gouraud_render_stops_on_interrupt() {
        use crate::render::gather::tests::{furnace, lit_rows, StopAfter};
        let (solved, tracer) = furnace();
        let cam = solved.scene.camera.unwrap();
        for shading in [Shading::Gouraud, Shading::Flat] {
            let opts = Options { width: 32, height: 256, spp_axis: 2, shading };
            assert_eq!(lit_rows(&solved.render(&cam, &opts, &tracer, &crate::NoProgress)), 256);
            let stop = StopAfter::new(5);
            let img = solved.render(&cam, &opts, &tracer, &stop);
            assert!(stop.done() <= 5 + rayon::current_num_threads() as u64, "{} rows after a stop at 5", stop.done());
            assert_eq!(lit_rows(&img) as u64, stop.done());
        }
    }

    #[test]
    fn inverse_bilinear_roundtrip() {
        let c = [
            DVec3::new(0., 0., 0.),
            DVec3::new(2., 0., 0.1),
            DVec3::new(2.5, 1.5, 0.1),
            DVec3::new(-0.2, 1.0, 0.0),
        ];
        // Make it planar: project onto z = 0.
        let c = c.map(|p| DVec3::new(p.x, p.y, 0.0));
        for &(u, v) in &[(0.1, 0.2), (0.5, 0.5), (0.9, 0.7), (0.0, 1.0)] {
            let p = c[0].lerp(c[1], u).lerp(c[3].lerp(c[2], u), v);
            let (uu, vv) = inverse_bilinear(p, &c, DVec3::Z);
            assert!((uu - u).abs() < 1e-9 && (vv - v).abs() < 1e-9, "{u},{v} -> {uu},{vv}");
        }
    }
}
