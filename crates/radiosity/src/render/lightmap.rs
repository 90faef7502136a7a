//! Lightmap texels: the final gather ([`super::gather::Shader`]) evaluated at the centre of
//! every texel of an atlas ([`crate::mesh::atlas`]) instead of at camera-ray hits. Direct
//! light is exact per texel (soft shadows of emitters, the sun's and the lights' sharp
//! ones, whatever the mesh), indirect light comes from the solution as in images.
//!
//! Texels are assigned by rasterising every element in its chart's texel space (a texel
//! belongs to the element that holds its centre). Texels of a chart's rectangle that no
//! element holds — outside the polygons, along their edges, and the padding — are then
//! filled by dilation: repeatedly the mean of their filled neighbours in the same chart,
//! so bilinear filtering at a chart's border never reads an unfilled (black) texel. A chart
//! too small to hold any texel centre gets its elements' area-mean radiance throughout.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::gather::{Indirect, Options, Patterns, Shader};
use super::Image;
use crate::accel::SceneRays;
use crate::mesh::atlas::Atlas;
use crate::mesh::Mesh;
use crate::sampling::rng_for;
use crate::scene::Scene;
use crate::{Progress, Rgb};

/// What was drawn.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    /// Texels shaded by the final gather (their centre lies on an element).
    pub shaded: usize,
    /// Texels filled by dilation (edges and padding).
    pub dilated: usize,
    /// Texels of charts that hold no texel centre, set to the chart's mean.
    pub flat: usize,
    /// Rays cast.
    pub rays: u64,
}

/// The element holding each texel centre (u32::MAX: none), by rasterising every element's
/// triangles in its chart's texel coordinates.
fn rasterise(mesh: &Mesh, atlas: &Atlas) -> Vec<u32> {
    let n = atlas.size;
    let mut owner = vec![u32::MAX; n * n];
    for (e, el) in mesh.elements.iter().enumerate() {
        let (c, k) = el.corners(&mesh.positions);
        let t: Vec<(f64, f64)> = (0..k).map(|i| atlas.texel_coords(el.patch, c[i])).collect();
        let tris: &[[usize; 3]] = if k == 4 { &[[0, 1, 2], [0, 2, 3]] } else { &[[0, 1, 2]] };
        for tri in tris {
            let (a, b, cc) = (t[tri[0]], t[tri[1]], t[tri[2]]);
            let area = (b.0 - a.0) * (cc.1 - a.1) - (b.1 - a.1) * (cc.0 - a.0);
            if area.abs() < 1e-18 {
                continue;
            }
            let x0 = a.0.min(b.0).min(cc.0).floor().max(0.0) as usize;
            let x1 = (a.0.max(b.0).max(cc.0).ceil() as usize).min(n);
            let y0 = a.1.min(b.1).min(cc.1).floor().max(0.0) as usize;
            let y1 = (a.1.max(b.1).max(cc.1).ceil() as usize).min(n);
            let eps = -1e-9 * area.abs();
            for y in y0..y1 {
                for x in x0..x1 {
                    let p = (x as f64 + 0.5, y as f64 + 0.5);
                    let edge = |u: (f64, f64), v: (f64, f64)| ((v.0 - u.0) * (p.1 - u.1) - (v.1 - u.1) * (p.0 - u.0)) * area.signum();
                    if edge(a, b) >= eps && edge(b, cc) >= eps && edge(cc, a) >= eps && owner[y * n + x] == u32::MAX {
                        owner[y * n + x] = e as u32;
                    }
                }
            }
        }
    }
    owner
}

/// What a lightmap's texels hold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Quantity {
    /// Outgoing radiance `L = Le + ρ·E/π` (what a display shows; texture detail at the
    /// lightmap's resolution).
    #[default]
    Radiance,
    /// Irradiance `E` arriving at the surface (W/m² or scene units), which a viewer
    /// multiplies by its own base colour (texture included) over π: the `MOZ_lightmap`
    /// convention of three.js's `lightMap`.
    Irradiance,
}

/// Renders the lightmap of `atlas`: per texel (linear) the `quantity`; `element_l` is each
/// element's value of it (radiance `B/π`, or irradiance) for charts too small to hold a
/// texel. `opts` gives the shadow and gather rays per texel and the seed (its size and
/// samples per pixel are not used: one position per texel, at its centre).
#[allow(clippy::too_many_arguments)]
pub fn render(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    indirect: &Indirect,
    atlas: &Atlas,
    element_l: &[Rgb],
    quantity: Quantity,
    opts: &Options,
    progress: &dyn Progress,
) -> (Image, Stats) {
    let n = atlas.size;
    let owner = rasterise(mesh, atlas);
    // Chart of every texel of a chart's rectangle (u32::MAX: outside every chart).
    let mut chart = vec![u32::MAX; n * n];
    for (c, ch) in atlas.charts.iter().enumerate() {
        for y in ch.y..ch.y + ch.height {
            chart[y * n + ch.x..y * n + ch.x + ch.width].fill(c as u32);
        }
    }
    let shader = Shader::new(scene, mesh, rays, indirect, opts);
    let mut img = Image::new(n, n);
    let stopped = AtomicBool::new(false);
    progress.begin("lightmap", n as u64);
    let rays_cast: u64 = img
        .pixels
        .par_chunks_mut(n)
        .enumerate()
        .map(|(y, row)| {
            if stopped.load(Ordering::Relaxed) || progress.should_stop() {
                stopped.store(true, Ordering::Relaxed);
                return 0;
            }
            let mut pat = Patterns::default();
            let mut cast = 0;
            for (x, px) in row.iter_mut().enumerate() {
                let e = owner[y * n + x];
                if e == u32::MAX {
                    continue;
                }
                let p = atlas.world(mesh.elements[e as usize].patch, x as f64 + 0.5, y as f64 + 0.5);
                let mut rng = rng_for(opts.seed, (y * n + x) as u64);
                shader.draw(1, 1, &mut rng, &mut pat);
                let (l, r) = match quantity {
                    Quantity::Radiance => shader.shade(e, p, 0, atlas.texel * atlas.texel, &mut pat),
                    Quantity::Irradiance => shader.irradiance(e, p, 0, &mut pat),
                };
                *px = l;
                cast += r + 1;
            }
            progress.advance(1);
            cast
        })
        .sum();
    progress.end();

    // Dilation inside each chart's rectangle.
    let mut filled: Vec<bool> = owner.iter().map(|&o| o != u32::MAX).collect();
    let mut stats = Stats { shaded: filled.iter().filter(|&&f| f).count(), rays: rays_cast, ..Default::default() };
    loop {
        let next: Vec<(usize, Rgb)> = (0..n)
            .into_par_iter()
            .flat_map_iter(|y| {
                let (img, filled, chart) = (&img, &filled, &chart);
                (0..n).filter_map(move |x| {
                    let i = y * n + x;
                    if filled[i] || chart[i] == u32::MAX {
                        return None;
                    }
                    let (mut sum, mut k) = (Rgb::ZERO, 0);
                    for yy in y.saturating_sub(1)..(y + 2).min(n) {
                        for xx in x.saturating_sub(1)..(x + 2).min(n) {
                            let j = yy * n + xx;
                            if filled[j] && chart[j] == chart[i] {
                                sum += img.pixels[j];
                                k += 1;
                            }
                        }
                    }
                    (k > 0).then(|| (i, sum / k as f64))
                })
            })
            .collect();
        if next.is_empty() {
            break;
        }
        stats.dilated += next.len();
        for (i, v) in next {
            img.pixels[i] = v;
            filled[i] = true;
        }
    }
    // Charts that hold no texel centre: their elements' area-mean radiance.
    let mut sums = vec![(Rgb::ZERO, 0.0); atlas.charts.len()];
    for (e, el) in mesh.elements.iter().enumerate() {
        let s = &mut sums[atlas.chart_of[el.patch as usize] as usize];
        s.0 += element_l[e] * el.area;
        s.1 += el.area;
    }
    for (ch, (sum, area)) in atlas.charts.iter().zip(sums) {
        if filled[ch.y * n + ch.x] {
            continue;
        }
        let mean = if area > 0.0 { sum / area } else { Rgb::ZERO };
        for y in ch.y..ch.y + ch.height {
            img.pixels[y * n + ch.x..y * n + ch.x + ch.width].fill(mean);
        }
        stats.flat += ch.width * ch.height;
    }
    (img, stats)
}
