//! Final gather: per pixel, direct light computed exactly, indirect light taken from the
//! radiosity solution (the two-pass method; Reichert 1992, Lischinski, Tampieri &
//! Greenberg 1992 "Combining hierarchical radiosity and discontinuity meshing").
//!
//! For a visible point `x` with reflectance ρ and emission `L_e`:
//!
//! ```text
//! L(x) = L_e(x) + ρ(x)/π · ( H_direct(x) + H_indirect(x) )
//! H_direct(x)   = Σ_emitters  π·L_e,Q · F(dA_x → Q) · V̂(x, Q)
//! H_indirect(x) = ∫_Ω (B − E)(y(x, ω)) cos θ dω / π  = Σ_j F(dA_x → j) (B_j − E_j)
//! ```
//!
//! `F(dA_x → Q)` is the exact contour integral ([`crate::form_factor::analytic::point_factor`]) and `V̂` the
//! fraction of stratified shadow rays to the emitter polygon that reach it, so direct light
//! and its soft shadows are resolved per pixel, whatever the mesh. The indirect irradiance
//! (light that has bounced at least once) is read in one of two ways ([`Indirect`]):
//!
//! - **gathered** (the default on the hierarchical transport and for the stochastic
//!   solvers): cosine-distributed rays from `x` itself, each reading the
//!   reflected radiosity `B − E` of the element it meets — the one-bounce final gather of
//!   Reichert 1992 and of photon-map renderers (Jensen 1996). `x`'s own view of the scene
//!   is resolved per pixel (contact shadows under furniture, corners), only the light
//!   leaving the surfaces it sees comes from the mesh;
//! - **interpolated** (the default on form-factor rows): the element values
//!   `(F·(B − E))_i` from the transport operator, reconstructed per vertex like Gouraud
//!   radiosity. No rays and no noise, but as coarse as the mesh and as biased as `F` per
//!   element (the hierarchy's links: on the conference room the first bounce read this way
//!   is 5 % dark where the gathered one agrees with a path tracer's to 0.1 %;
//!   BENCHMARKS.md "Fifth round"). Gathering is noisy where the radiosity seen varies
//!   strongly (a bright spot under a lamp): on the Cornell box 2 × 2 rays per position
//!   give 3.8 % against 1.6 % interpolated from exact rows.
//!
//! Under a sky ([`crate::scene::Sky`]) a camera ray that meets nothing shows the sky's
//! radiance, and the sky's direct irradiance `π L_sky S(x)` ([`crate::sky`]) is estimated
//! per position by cosine-distributed rays: the gather rays themselves when gathering (a
//! ray that leaves the scene reads `π L_sky` where one that meets an element reads its
//! `B − E`), [`SKY_AXIS`]² rays of their own per position when interpolating. A sun adds
//! `E_sun · max(0, n·ω) · V` per position with `shadow × shadow` rays in its disk (sharp
//! shadows), and a camera ray that meets its disk shows its radiance. Through sky portals
//! ([`crate::scene::Portal`]: the openings a scene's author marks, as in pbrt-v4 and
//! Mitsuba) the sky's direct light is sampled in solid angle instead (`portal_irradiance`,
//! one direction per shadow point, uniform over the portals' spherical triangles; Arvo
//! 1995), and gather or sky rays that leave the scene through a portal read nothing, so each
//! direction is counted once whatever the portals cover. Point, spot and
//! directional lights ([`crate::lights`]) add their exact direct irradiance per position,
//! one shadow ray each (hard shadows); they are not seen by the camera.
//!
//! Pixels average `spp × spp` stratified positions (box filter); shadow and gather rays are
//! stratified over the whole pixel; each pixel draws its own random stream (seed, pixel),
//! so images do not depend on the thread count. Sampling is adaptive ([`Options::noise`]):
//! every pixel takes 8 positions, then those whose mean is still noisy (standard error
//! against the pixel's value, with the variance taken from its neighbourhood) or that
//! differ from a neighbour (an edge) take more, up to `spp²` — the classic adaptive
//! supersampling (Mitchell 1987, "Generating antialiased images at low sampling
//! densities"), with a per-pixel error test in place of a contrast test alone.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::gouraud::{interpolate, ElementTracer};
use super::{Image, PinholeCamera};
use crate::accel::SceneRays;
use crate::direct::{direct_irradiance, direct_irradiance_sampled, emitters, LOOP_EMITTERS};
use crate::mesh::{Locator, Mesh};
use crate::sampling::{rng_for, stratified};
use crate::scene::Scene;
use crate::sky::{through_portal, PortalTriangle};
use crate::{Progress, Rgb};

/// Sky rays per position, as `n × n` stratified cosine directions, when the indirect light
/// is interpolated (gathering reads the sky through its own rays). The sky's direct light
/// is a visibility average over the hemisphere, the noisiest term of an open scene: on
/// Sponza's courtyard (BENCHMARKS.md, "Sky") 2 × 2 rays per position give 5.5 % against the
/// path tracer, 4 × 4 give 3.3 %.
pub const SKY_AXIS: usize = 4;

/// Final-gather options.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Positions per pixel along each axis (box filter).
    pub spp_axis: usize,
    /// Shadow rays per position and emitter, as `n × n` stratified points.
    pub shadow_axis: usize,
    /// Indirect rays per position, as `n × n` stratified directions (with
    /// [`Indirect::Gathered`]; ignored by [`Indirect::Interpolated`]).
    pub gather_axis: usize,
    /// Seed of the pixel streams.
    pub seed: u64,
    /// Adaptive sampling's target: the standard error of a pixel's mean luminance as a
    /// share of that mean (or of a floor for dark pixels; see [`render`]); 0 takes every
    /// `spp_axis²` position in every pixel.
    pub noise: f64,
}

/// Where the final gather takes its indirect light from (see the module docs).
pub enum Indirect {
    /// Indirect irradiance per mesh vertex, interpolated at each visible point.
    Interpolated(Vec<Rgb>),
    /// Reflected radiosity `B − E` per element, read by gather rays from each visible
    /// point; `locator` finds the element a ray meets on its polygon.
    Gathered {
        /// `B − E` per element.
        reflected: Vec<Rgb>,
        /// Point location on the mesh.
        locator: Locator,
    },
}

/// One pixel's stratified points for its first `positions` positions, `axis²` per
/// position: the unit square is split into `axis × axis` strata, each stratum into
/// `side × side` cells (`side²` = the pixel's positions). Position `k` takes one jittered
/// cell in every stratum — the `k`-th of that stratum's cells in a random order (a partial
/// Fisher–Yates shuffle per stratum) — so each position's points are stratified over the
/// whole square, any set of positions is stratified stratum by stratum, and all `side²`
/// positions together take every one of the `(side·axis)²` cells. (Until 2026-12-05 a
/// position took `axis²` cells drawn from the whole grid: stratified only once every
/// position was taken, so the per-position variance that adaptive sampling reads was that
/// of random points.) Position `k`'s points are `out[k·axis² .. (k+1)·axis²]`. The draws for
/// some positions are a prefix of those for more, so a pixel can take more positions later
/// from the same stream (adaptive sampling) and draws nothing for positions it never
/// takes.
fn pixel_pattern(side: usize, axis: usize, positions: usize, rng: &mut crate::sampling::Rng, cells: &mut Vec<u32>, out: &mut Vec<(f64, f64)>) {
    use rand::RngExt;
    let per = side * side;
    let positions = positions.min(per);
    let strata = axis * axis;
    cells.clear();
    for _ in 0..strata {
        cells.extend(0..per as u32);
    }
    out.clear();
    let fine = 1.0 / (side * axis) as f64;
    for k in 0..positions {
        for t in 0..strata {
            let own = &mut cells[t * per..(t + 1) * per];
            own.swap(k, rng.random_range(k..per));
            let c = own[k] as usize;
            let (i, j) = ((t % axis) * side + c % side, (t / axis) * side + c / side);
            let (a, b): (f64, f64) = (rng.random(), rng.random());
            out.push(((i as f64 + a) * fine, (j as f64 + b) * fine));
        }
    }
}

/// The stream of one pattern of a pixel: pattern `tag` of the pixel whose stream gave
/// `base`.
fn pattern_rng(base: u64, tag: u64) -> crate::sampling::Rng {
    use rand::SeedableRng;
    crate::sampling::Rng::seed_from_u64(crate::sampling::mix64(base ^ crate::sampling::mix64(tag.wrapping_add(0x7061_7474))))
}

/// The light sources and settings of the final gather, shared by every position it shades:
/// image pixels ([`render`]) and lightmap texels ([`crate::render::lightmap`]).
pub struct Shader<'a> {
    scene: &'a Scene,
    mesh: &'a Mesh,
    rays: &'a SceneRays,
    indirect: &'a Indirect,
    ems: Vec<crate::direct::Emitter>,
    /// The lit sky (its radiance by direction; None: black).
    sky: Option<&'a crate::scene::Sky>,
    sun: Option<crate::scene::Sun>,
    /// The lit sky's portals (empty without a lit sky).
    portals: &'a [crate::scene::Portal],
    shadow_axis: usize,
    /// Gather (or sky) rays per position along each axis; 0: none.
    gather_axis: usize,
}

/// The random points one pixel (or texel) draws for its `positions` positions: one shadow
/// pattern per emitter looped over (one shared when they are sampled), the gather
/// directions, the sun's points.
#[derive(Default)]
pub struct Patterns {
    shadows: Vec<Vec<(f64, f64)>>,
    gather: Vec<(f64, f64)>,
    sun: Vec<(f64, f64)>,
    /// The sky portals' points (a stream of their own, uncorrelated with the lamps').
    portal: Vec<(f64, f64)>,
    /// Scratch for `portal_irradiance`: the portals' spherical triangles at one position.
    portal_tris: Vec<PortalTriangle>,
    /// The lamp choice, shared by the positions of one pixel (or texel) on one polygon.
    choice: crate::direct::EmitterChoice,
    cells: Vec<u32>,
}

impl<'a> Shader<'a> {
    /// The shader of a solved scene; `opts` gives the shadow and gather rays per position.
    pub fn new(scene: &'a Scene, mesh: &'a Mesh, rays: &'a SceneRays, indirect: &'a Indirect, opts: &Options) -> Self {
        let sky = scene.lit_sky().filter(|s| s.has_radiance());
        let gather_axis = match indirect {
            Indirect::Gathered { .. } => opts.gather_axis.max(1),
            // Rays for the sky alone (with portals, for the sky outside them).
            Indirect::Interpolated(_) if scene.lit_sky().is_some_and(|s| s.portals.is_empty()) => SKY_AXIS,
            Indirect::Interpolated(_) if scene.lit_sky().is_some() => 2,
            Indirect::Interpolated(_) => 0,
        };
        Shader {
            scene,
            mesh,
            rays,
            indirect,
            ems: emitters(scene),
            sky,
            sun: scene.lit_sky().and_then(|s| s.lit_sun()),
            portals: sky.map_or(&[][..], |s| &s.portals[..]),
            shadow_axis: opts.shadow_axis.max(1),
            gather_axis,
        }
    }

    /// Draws the random points of the first `positions` of one pixel's `side × side`
    /// positions; drawn again from the same `rng` state with more positions, the first ones
    /// are the same. Takes one number from `rng`; each pattern has a stream of its own.
    pub fn draw(&self, side: usize, positions: usize, rng: &mut crate::sampling::Rng, pat: &mut Patterns) {
        use rand::RngExt;
        let base: u64 = rng.random();
        pat.choice.reset();
        let npat = if self.ems.len() <= LOOP_EMITTERS { self.ems.len() } else { 1 };
        pat.shadows.resize_with(npat, Vec::new);
        for (t, p) in pat.shadows.iter_mut().enumerate() {
            pixel_pattern(side, self.shadow_axis, positions, &mut pattern_rng(base, t as u64 + 2), &mut pat.cells, p);
        }
        if self.gather_axis > 0 {
            pixel_pattern(side, self.gather_axis, positions, &mut pattern_rng(base, 0), &mut pat.cells, &mut pat.gather);
        }
        if self.sun.is_some() {
            pixel_pattern(side, self.shadow_axis, positions, &mut pattern_rng(base, 1), &mut pat.cells, &mut pat.sun);
        }
        if !self.portals.is_empty() {
            pixel_pattern(side, self.shadow_axis, positions, &mut pattern_rng(base, u64::MAX), &mut pat.cells, &mut pat.portal);
        }
    }

    /// What a camera ray in direction `dir` that meets nothing sees: the sky, and the
    /// sun's disk.
    pub fn background(&self, dir: glam::DVec3) -> Rgb {
        let mut l = self.sky.map_or(Rgb::ZERO, |s| s.radiance_in(dir, 0.0));
        if let Some(sun) = &self.sun {
            if dir.normalize().dot(sun.direction) >= sun.cos_radius() && sun.angular_diameter_deg > 0.0 {
                l += sun.radiance();
            }
        }
        l
    }

    /// Outgoing radiance at `p` on the front of element `e`, with the `k`-th position's
    /// share of `pat`; textures are read filtered over `footprint` (the area, in scene
    /// units², that the sample stands for). Returns the radiance and the rays cast.
    pub fn shade(&self, e: u32, p: glam::DVec3, k: usize, footprint: f64, pat: &mut Patterns) -> (Rgb, u64) {
        let patch = self.mesh.elements[e as usize].patch as usize;
        let l = self.scene.emission_at(patch, p, footprint);
        let rho = self.scene.reflectance_at(patch, p, footprint);
        if rho.max_element() <= 0.0 {
            return (l, 0);
        }
        let (h, nrays) = self.irradiance(e, p, k, pat);
        (l + rho * h * (1.0 / std::f64::consts::PI), nrays)
    }

    /// Irradiance arriving at `p` on the front of element `e` (direct light of emitters,
    /// the sun and the lights, and the indirect light), with the `k`-th position's share
    /// of `pat`: what [`Shader::shade`] multiplies by ρ/π. Returns it and the rays cast.
    pub fn irradiance(&self, e: u32, p: glam::DVec3, k: usize, pat: &mut Patterns) -> (Rgb, u64) {
        let (scene, mesh, rays) = (self.scene, self.mesh, self.rays);
        let el = &mesh.elements[e as usize];
        let m2 = self.shadow_axis * self.shadow_axis;
        let mut nrays = 0;
        let (mut hd, r) = if self.ems.len() <= LOOP_EMITTERS {
            let shadows = &pat.shadows;
            direct_irradiance(scene, rays, &self.ems, p, el.normal, el.patch, |em| &shadows[em][k * m2..(k + 1) * m2])
        } else {
            let pts = &pat.shadows[0][k * m2..(k + 1) * m2];
            direct_irradiance_sampled(scene, rays, &self.ems, p, el.normal, el.patch, pts, &mut pat.choice)
        };
        nrays += r;
        if let Some(sun) = &self.sun {
            let pts = &pat.sun[k * m2..(k + 1) * m2];
            let (f, r) = crate::sky::sun_factor_at(rays, sun, p, el.normal, el.patch, pts);
            hd += sun.irradiance * f;
            nrays += r;
        }
        if let (Some(sky), false) = (self.sky, self.portals.is_empty()) {
            let pts = &pat.portal[k * m2..(k + 1) * m2];
            let (h, r) = portal_irradiance(rays, sky, self.portals, p, el.normal, el.patch, pts, &mut pat.portal_tris);
            hd += h;
            nrays += r;
        }
        if !scene.lights.is_empty() {
            let (hl, r) = crate::lights::lights_at(rays, &scene.lights, p, el.normal, el.patch);
            hd += hl;
            nrays += r;
        }
        let g2 = self.gather_axis * self.gather_axis;
        let dirs = &pat.gather[k * g2..(k + 1) * g2];
        nrays += g2 as u64;
        // Exitance π·L of the sky seen by a gather ray that leaves the scene, the image read
        // over the ray's share of the hemisphere.
        let share = std::f64::consts::TAU / g2.max(1) as f64;
        let sky = |dir: glam::DVec3| self.sky.map_or(Rgb::ZERO, |s| s.radiance_in(dir, share) * std::f64::consts::PI);
        let hi = match self.indirect {
            Indirect::Interpolated(hv) if g2 > 0 => {
                interpolate(mesh, e, p, hv) + gathered(mesh, rays, None, &sky, self.portals, p, el.normal, el.patch, dirs)
            }
            Indirect::Interpolated(hv) => interpolate(mesh, e, p, hv),
            Indirect::Gathered { reflected, locator } => {
                gathered(mesh, rays, Some((locator, reflected)), &sky, self.portals, p, el.normal, el.patch, dirs)
            }
        };
        (hd + hi, nrays)
    }
}

/// Positions per round of adaptive sampling: one in each quadrant of the pixel.
const ROUND: usize = 4;

/// Positions every pixel takes before adaptive sampling judges its noise (whole rounds).
/// Fewer misjudge too many pixels (Cornell box: 4 first positions 1.68 %, 8 1.64 %
/// against 1.63 % taking all 36; BENCHMARKS.md "Adaptive pixel sampling").
pub const ADAPTIVE_FIRST: usize = 8;

/// The noise floor of adaptive sampling, as a share of the image's typical luminance: a
/// pixel darker than this is judged against the floor instead of its own mean. Half the
/// typical luminance let dark pixels with heavy-tailed direct light (the classroom's 24
/// lamps, sampled) stop early with twice the noise; a quarter does not.
pub const ADAPTIVE_FLOOR: f64 = 0.25;

/// A pixel whose mean (after the first positions) differs from a 4-neighbour's by more
/// than this share of the brighter one takes every position: an edge, or a thin feature
/// that the first positions of one of them missed.
pub const ADAPTIVE_CONTRAST: f64 = 0.1;

/// ... and by more than this many standard errors of their difference: a difference
/// that noise explains is left to the variance test. Without it, noise alone made edges of
/// a third of the classroom's pixels (95 k of 262 k after 8 positions; 36 k with it, the
/// image unchanged) and their variance, between surfaces rather than of one estimate,
/// spread over their neighbours through [`ADAPTIVE_POOL_RADIUS`].
pub const ADAPTIVE_SIGNIFICANCE: f64 = 3.0;

/// The per-position variance that judges a pixel is the largest over the `(2r+1)²`
/// pixels around it, `r` this: eight positions alone miss the rare bright sample of a
/// heavy-tailed estimate (a lamp picked with a poor guide), their neighbours see it. Edge
/// pixels are left out of their neighbours' pool (their variance is that of the surfaces
/// they straddle). The mean over the pool instead of the largest: classroom 27.0 of 36
/// positions per pixel, 3.45 % against its 12 × 12 render, against 29.3 and 3.37 %.
pub const ADAPTIVE_POOL_RADIUS: usize = 2;

/// The default of [`Options::noise`] (the CLI's `--pixel-noise`): a pixel stops once the
/// standard error of its mean is 1 % of that mean.
pub const DEFAULT_NOISE: f64 = 0.01;

/// The mean luminance of the pixels taken so far, leaving out those brighter than 20 × the
/// median (lamps seen directly, which the image error leaves out too).
fn typical_luminance(sums: &[PixelSums]) -> f64 {
    let mut lum: Vec<f64> = sums.iter().filter(|p| p.taken > 0).map(PixelSums::mean).collect();
    if lum.is_empty() {
        return 0.0;
    }
    let mid = lum.len() / 2;
    let median = *lum.select_nth_unstable_by(mid, f64::total_cmp).1;
    let kept: Vec<f64> = lum.into_iter().filter(|&l| l <= 20.0 * median).collect();
    kept.iter().sum::<f64>() / kept.len().max(1) as f64
}

/// The cells (`j·s + i`) of an `s × s` pixel grid, by quadrant of the pixel.
fn quadrants(s: usize) -> [Vec<usize>; 4] {
    let half = s.div_ceil(2);
    let mut quads: [Vec<usize>; 4] = Default::default();
    for j in 0..s {
        for i in 0..s {
            quads[usize::from(i >= half) + 2 * usize::from(j >= half)].push(j * s + i);
        }
    }
    quads
}

/// The order in which one pixel takes its stratified positions: round-robin over the
/// pixel's quadrants, each quadrant's cells in random order, so that every prefix of whole
/// rounds is spread over the pixel and is an unbiased choice among its cells.
fn position_order(quads: &[Vec<usize>; 4], rng: &mut crate::sampling::Rng, scratch: &mut [Vec<usize>; 4], out: &mut Vec<usize>) {
    use rand::RngExt;
    out.clear();
    for (q, cells) in scratch.iter_mut().zip(quads) {
        q.clone_from(cells);
        for i in (1..q.len()).rev() {
            q.swap(i, rng.random_range(0..=i));
        }
    }
    let longest = scratch.iter().map(Vec::len).max().unwrap_or(0);
    for r in 0..longest {
        out.extend(scratch.iter().filter_map(|q| q.get(r)));
    }
}

/// One pixel's drawn points: sub-pixel positions, their order, the shadow and gather
/// patterns.
#[derive(Default)]
struct PixelDraw {
    sub: Vec<(f64, f64)>,
    order: Vec<usize>,
    quads: [Vec<usize>; 4],
    pat: Patterns,
}

/// Bytes per pixel the final gather holds besides the image: its [`PixelSums`] and, for
/// adaptive sampling, each pixel's own and neighbourhood variance and its edge flag.
pub const PIXEL_STATE_BYTES: u64 = std::mem::size_of::<PixelSums>() as u64 + 2 * 8 + 1;

/// One pixel's running sums: radiance, and the luminance's first two moments over the
/// positions taken.
#[derive(Clone, Copy, Default)]
struct PixelSums {
    radiance: Rgb,
    lum: f64,
    lum2: f64,
    taken: u32,
}

impl PixelSums {
    /// The mean luminance of the positions taken (0 before any).
    fn mean(&self) -> f64 {
        self.lum / f64::from(self.taken.max(1))
    }

    /// The sample variance of the luminance of one position.
    fn variance(&self) -> f64 {
        let n = self.taken as f64;
        if self.taken < 2 {
            return 0.0;
        }
        ((self.lum2 - self.lum * self.lum / n) / (n - 1.0)).max(0.0)
    }

    /// Whether the standard error of the pixel's mean luminance, with per-position variance
    /// `var`, is within `noise` of `max(mean, floor)`.
    fn converged(&self, var: f64, noise: f64, floor: f64) -> bool {
        self.taken >= 2 && var / self.taken as f64 <= (noise * self.mean().max(floor)).powi(2)
    }
}

/// What one final-gather image took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sampling {
    /// Rays cast (camera, shadow, gather and sky rays).
    pub rays: u64,
    /// Pixel positions shaded, over all pixels.
    pub positions: u64,
    /// Pixels drawn.
    pub pixels: u64,
}

impl Sampling {
    /// Mean positions per pixel drawn.
    pub fn positions_per_pixel(&self) -> f64 {
        self.positions as f64 / self.pixels.max(1) as f64
    }
}

/// Renders by final gathering, with the indirect light from `indirect` (see the module
/// docs). Returns the image and what it took (rays, positions).
///
/// With `opts.noise > 0` the sampling is adaptive: every pixel first takes
/// [`ADAPTIVE_FIRST`] of its `spp²` positions (whole rounds of one per quadrant, see
/// [`position_order`]); then, in a second pass, each pixel whose mean luminance has a
/// standard error above `noise · max(mean, floor)` takes further rounds until it is below
/// or all `spp²` positions are taken. `floor` is [`ADAPTIVE_FLOOR`] times the first pass's
/// mean pixel luminance (pixels brighter than 20 × its median, the lamps, left out): the
/// image's relative RMSE is an error against its mean, so dark pixels need not reach the
/// same relative error as lit ones. Edges, penumbrae and textures show as variance between
/// positions and take every position; smooth lit surfaces stop early. A pixel's positions
/// and rays are the same as without adaptivity, in the same order, so `noise = 0` draws the
/// fixed-sampling image.
#[allow(clippy::too_many_arguments)]
pub fn render(
    scene: &Scene,
    mesh: &Mesh,
    rays: &SceneRays,
    tracer: &ElementTracer,
    indirect: &Indirect,
    cam: &PinholeCamera,
    opts: &Options,
    progress: &dyn Progress,
) -> (Image, Sampling) {
    let (w, h) = (opts.width, opts.height);
    let s = opts.spp_axis.max(1);
    let all = s * s;
    let adaptive = opts.noise > 0.0 && all > ADAPTIVE_FIRST;
    let first = if adaptive { ADAPTIVE_FIRST } else { all };
    let quads = quadrants(s);
    let shader = Shader::new(scene, mesh, rays, indirect, opts);
    let pixel_angle = cam.pixel_angle() / s as f64;
    progress.begin("final gather", if adaptive { 2 * h as u64 } else { h as u64 });
    let stopped = AtomicBool::new(false);
    // Draws pixel (x, y)'s sub-pixel points and patterns from its own stream (the same
    // every time).
    let draw = |x: usize, y: usize, positions: usize, px: &mut PixelDraw| {
        let mut rng = rng_for(opts.seed, (y * w + x) as u64);
        stratified(s, &mut rng, &mut px.sub);
        shader.draw(s, positions, &mut rng, &mut px.pat);
        position_order(&quads, &mut rng, &mut px.quads, &mut px.order);
    };
    // Takes positions `from..to` (in `order`) of pixel (x, y), drawn, into `acc`.
    let take = |x: usize, y: usize, from: usize, to: usize, acc: &mut PixelSums, px: &mut PixelDraw| -> u64 {
        let mut nrays = 0u64;
        for k in from..to {
            let (sx, sy) = px.sub[px.order[k]];
            let dir = cam.direction(x as f64 + sx, y as f64 + sy);
            nrays += 1;
            let l = match tracer.trace(cam.eye, dir) {
                None => shader.background(dir),
                // Back side of a one-sided surface: black.
                Some((e, _)) if mesh.elements[e as usize].normal.dot(dir) >= 0.0 => Rgb::ZERO,
                Some((e, p)) => {
                    // The sub-pixel's footprint on the surface, for texture filtering.
                    let cos = mesh.elements[e as usize].normal.dot(dir).abs() / dir.length();
                    let r_angle = (p - cam.eye).length() * pixel_angle;
                    let footprint = r_angle * r_angle / cos.max(0.05);
                    let (l, r) = shader.shade(e, p, k, footprint, &mut px.pat);
                    nrays += r;
                    l
                }
            };
            let lum = crate::luminance(l);
            acc.radiance += l;
            acc.lum += lum;
            acc.lum2 += lum * lum;
            acc.taken += 1;
        }
        nrays
    };
    // One pass over the image's rows, in parallel: `row` shades one row and returns its rays;
    // a stop request ends the pass (rows begun finish).
    let pass = |sums: &mut [PixelSums], row: &(dyn Fn(usize, &mut [PixelSums], &mut PixelDraw) -> u64 + Sync)| -> u64 {
        sums.par_chunks_mut(w)
            .enumerate()
            .map(|(y, pixels)| {
                if stopped.load(Ordering::Relaxed) || progress.should_stop() {
                    stopped.store(true, Ordering::Relaxed);
                    return 0;
                }
                let nrays = row(y, pixels, &mut PixelDraw::default());
                progress.advance(1);
                nrays
            })
            .sum()
    };
    let mut sums = vec![PixelSums::default(); w * h];
    let mut total_rays = pass(&mut sums, &|y, row, px| {
        let mut nrays = 0;
        for (x, acc) in row.iter_mut().enumerate() {
            draw(x, y, first, px);
            nrays += take(x, y, 0, first, acc, px);
        }
        nrays
    });
    if adaptive && !stopped.load(Ordering::Relaxed) {
        let floor = ADAPTIVE_FLOOR * typical_luminance(&sums);
        // The per-position variance that judges a pixel: the largest around it, edges
        // left out.
        let own: Vec<f64> = sums.par_iter().with_min_len(4096).map(PixelSums::variance).collect();
        // Edges (ADAPTIVE_CONTRAST, ADAPTIVE_SIGNIFICANCE) take every position, whatever
        // their own variance.
        let se2 = |i: usize| own[i] / f64::from(sums[i].taken.max(1));
        let edge = |x: usize, y: usize| {
            let k = y * w + x;
            let differs = |n: usize| {
                let (m, mn) = (sums[k].mean(), sums[n].mean());
                let d = m - mn;
                d.abs() > ADAPTIVE_CONTRAST * m.max(mn).max(floor) && d * d > ADAPTIVE_SIGNIFICANCE.powi(2) * (se2(k) + se2(n))
            };
            (x > 0 && differs(k - 1)) || (x + 1 < w && differs(k + 1)) || (y > 0 && differs(k - w)) || (y + 1 < h && differs(k + w))
        };
        let edges: Vec<bool> = (0..w * h).into_par_iter().with_min_len(4096).map(|k| edge(k % w, k / w)).collect();
        let pooled: Vec<f64> = (0..w * h)
            .into_par_iter()
            .with_min_len(4096)
            .map(|k| {
                let (x, y) = (k % w, k / w);
                let r = ADAPTIVE_POOL_RADIUS;
                let mut most = own[k];
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        if !edges[yy * w + xx] {
                            most = most.max(own[yy * w + xx]);
                        }
                    }
                }
                most
            })
            .collect();
        total_rays += pass(&mut sums, &|y, row, px| {
            let mut nrays = 0;
            for (x, acc) in row.iter_mut().enumerate() {
                let from = acc.taken as usize;
                if from == 0 || from >= all {
                    continue;
                }
                let k = y * w + x;
                let is_edge = edges[k];
                if !is_edge && acc.converged(pooled[k], opts.noise, floor) {
                    continue;
                }
                // The same points as the first pass's: redrawn from the pixel's stream.
                draw(x, y, all, px);
                if is_edge {
                    nrays += take(x, y, from, all, acc, px);
                    continue;
                }
                let mut from = from;
                // Further rounds judged by the pixel's own variance, kept no lower than the
                // pooled one.
                while from < all && !acc.converged(acc.variance().max(pooled[k]), opts.noise, floor) {
                    let to = (from + ROUND).min(all);
                    nrays += take(x, y, from, to, acc, px);
                    from = to;
                }
            }
            nrays
        });
    }
    progress.end();
    let mut img = Image::new(w, h);
    let mut sampling = Sampling { rays: total_rays, ..Default::default() };
    for (px, acc) in img.pixels.iter_mut().zip(&sums) {
        if acc.taken > 0 {
            *px = acc.radiance * (1.0 / acc.taken as f64);
            sampling.positions += u64::from(acc.taken);
            sampling.pixels += 1;
        }
    }
    (img, sampling)
}

/// The irradiance at `p` (normal `n`, on polygon `patch`) read by cosine-distributed rays
/// through the unit-square points `dirs`: a ray that meets the front of an element brings
/// its reflected radiosity (`elements` = the locator and `B − E`; None: nothing), one that
/// leaves the scene brings `sky` (the sky's exitance `π L_sky`, or zero), one that meets
/// the back of a one-sided surface nothing.
#[allow(clippy::too_many_arguments)]
#[inline]
fn gathered(
    mesh: &Mesh,
    rays: &SceneRays,
    elements: Option<(&Locator, &[Rgb])>,
    sky: &dyn Fn(glam::DVec3) -> Rgb,
    portals: &[crate::scene::Portal],
    p: glam::DVec3,
    n: glam::DVec3,
    patch: u32,
    dirs: &[(f64, f64)],
) -> Rgb {
    let (t, b) = crate::sampling::basis(n);
    let mut sum = Rgb::ZERO;
    for &(u1, u2) in dirs {
        let d = crate::sampling::cosine_hemisphere(u1, u2);
        let dir = t * d.x + b * d.y + n * d.z;
        let Some((locator, reflected)) = elements else {
            if !through_portal(portals, p, dir) && rays.escapes(p.as_vec3(), dir.as_vec3(), Some(patch)) {
                sum += sky(dir);
            }
            continue;
        };
        let hit = rays.closest_facing(p.as_vec3(), dir.as_vec3(), f32::INFINITY, Some(patch));
        if hit.is_none() {
            // Sky through a portal is the portal estimate's (`portal_irradiance`).
            if !through_portal(portals, p, dir) {
                sum += sky(dir);
            }
        } else if let Some(j) = locator.front_hit(mesh, rays, p, dir, hit) {
            sum += reflected[j as usize];
        }
    }
    sum * (1.0 / dirs.len() as f64)
}

/// The sky's irradiance at `p` (normal `n`, on polygon `patch`) through `portals`:
/// [`crate::sky::portal_integral`] of its radiance. Returns the irradiance and the rays
/// cast; `tris` is scratch (kept to spare an allocation per position).
#[allow(clippy::too_many_arguments)]
#[inline]
fn portal_irradiance(
    rays: &SceneRays,
    sky: &crate::scene::Sky,
    portals: &[crate::scene::Portal],
    p: glam::DVec3,
    n: glam::DVec3,
    patch: u32,
    pts: &[(f64, f64)],
    tris: &mut Vec<PortalTriangle>,
) -> (Rgb, u64) {
    crate::sky::portal_integral(rays, portals, p, n, patch, pts, tris, |d, share| sky.radiance_in(d, share))
}

#[cfg(test)]
pub(crate) mod tests {
    use std::sync::atomic::{AtomicU64, Ordering};

    use crate::pipeline::{solve_scene, Settings, Solved};
    use crate::render::gouraud::ElementTracer;
    use crate::scene::{builtin, Scene};
    use crate::Progress;

    /// Asks to stop once `after` units of progress (image rows) were reported.
    pub(crate) struct StopAfter {
        pub after: u64,
        pub done: AtomicU64,
    }
    impl StopAfter {
        pub fn new(after: u64) -> Self {
            StopAfter { after, done: AtomicU64::new(0) }
        }
        pub fn done(&self) -> u64 {
            self.done.load(Ordering::Relaxed)
        }
    }
    impl Progress for StopAfter {
        fn advance(&self, n: u64) {
            self.done.fetch_add(n, Ordering::Relaxed);
        }
        fn should_stop(&self) -> bool {
            self.done() >= self.after
        }
    }

    /// The furnace seen from its own camera (inside): every pixel shows a lit wall.
    pub(crate) fn furnace() -> (Solved, ElementTracer) {
        let scene = Scene::from_desc(builtin::furnace(0.5, 1.0)).unwrap();
        let solved = solve_scene(scene, &Settings { mesh_size: Some(0.25), ..Default::default() }, &crate::NoProgress).unwrap();
        let two: Vec<bool> = solved.scene.polygons.iter().map(|p| p.two_sided).collect();
        let tracer = ElementTracer::new(&solved.mesh, &two);
        (solved, tracer)
    }

    /// Rows with at least one lit pixel.
    pub(crate) fn lit_rows(img: &crate::render::Image) -> usize {
        img.pixels.chunks(img.width).filter(|r| r.iter().any(|p| p.max_element() > 0.0)).count()
    }

    #[test]
    fn final_gather_stops_on_interrupt() {
        let (solved, tracer) = furnace();
        let cam = solved.scene.camera.unwrap();
        let opts = super::Options { width: 32, height: 256, spp_axis: 2, shadow_axis: 1, gather_axis: 1, seed: 0, noise: 0.0 };
        let indirect = solved.indirect(true);
        let (full, _) = solved.render_gather(&cam, &opts, &tracer, &indirect, &crate::NoProgress);
        assert_eq!(lit_rows(&full), 256, "the furnace fills the image");
        let stop = StopAfter::new(3);
        let (img, _) = solved.render_gather(&cam, &opts, &tracer, &indirect, &stop);
        // Rows already started when the stop was seen finish; no other row is drawn.
        let most = 3 + rayon::current_num_threads() as u64;
        assert!(stop.done() <= most, "{} rows after a stop at 3", stop.done());
        assert_eq!(lit_rows(&img) as u64, stop.done());
    }

    /// Each position's points fall one in each of the `axis × axis` strata, all positions
    /// together one in each of the `(side·axis)²` cells, and the points of fewer positions
    /// are a prefix of those of more.
    #[test]
    fn pixel_pattern_stratifies_each_position_and_the_whole_pixel() {
        for (side, axis) in [(1usize, 2usize), (6, 2), (6, 4), (3, 3)] {
            let (mut cells, mut all, mut few) = (Vec::new(), Vec::new(), Vec::new());
            let per = axis * axis;
            super::pixel_pattern(side, axis, side * side, &mut super::pattern_rng(9, 0), &mut cells, &mut all);
            super::pixel_pattern(side, axis, 3, &mut super::pattern_rng(9, 0), &mut cells, &mut few);
            assert_eq!(all.len(), side * side * per);
            assert_eq!(few.len(), side.pow(2).min(3) * per);
            assert_eq!(&all[..few.len()], &few[..], "side {side}, axis {axis}: not a prefix");
            for (k, pos) in all.chunks(per).enumerate() {
                let mut strata: Vec<usize> = pos.iter().map(|&(u, v)| (u * axis as f64) as usize + axis * (v * axis as f64) as usize).collect();
                strata.sort_unstable();
                assert_eq!(strata, (0..per).collect::<Vec<_>>(), "side {side}, axis {axis}: position {k}");
            }
            let n = side * axis;
            let mut fine: Vec<usize> = all.iter().map(|&(u, v)| (u * n as f64) as usize + n * (v * n as f64) as usize).collect();
            fine.sort_unstable();
            assert_eq!(fine, (0..n * n).collect::<Vec<_>>(), "side {side}, axis {axis}: cells");
        }
    }

    /// Every prefix of whole rounds takes the same number of cells from each quadrant, and
    /// the whole order is a permutation of the cells.
    #[test]
    fn position_order_spreads_every_round_over_the_quadrants() {
        for s in [2usize, 4, 6, 8] {
            let quads = super::quadrants(s);
            let mut rng = crate::sampling::rng_for(1, s as u64);
            let (mut scratch, mut order) = (Default::default(), Vec::new());
            super::position_order(&quads, &mut rng, &mut scratch, &mut order);
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..s * s).collect::<Vec<_>>(), "s = {s}");
            let quadrant = |c: usize| usize::from(c % s >= s / 2) + 2 * usize::from(c / s >= s / 2);
            for (r, round) in order.chunks(4).enumerate() {
                let mut seen: Vec<usize> = round.iter().map(|&c| quadrant(c)).collect();
                seen.sort_unstable();
                assert_eq!(seen, vec![0, 1, 2, 3], "s = {s}, round {r}: {round:?}");
            }
        }
    }

    /// Where every position of a pixel reads the same value (the furnace: L = 2 everywhere)
    /// adaptive sampling stops after the first positions, and the image is as exact.
    #[test]
    fn adaptive_sampling_stops_early_where_the_image_is_exact() {
        let (solved, tracer) = furnace();
        let cam = solved.scene.camera.unwrap();
        let indirect = solved.indirect(true);
        let fixed = super::Options { width: 24, height: 24, spp_axis: 6, shadow_axis: 1, gather_axis: 1, seed: 3, noise: 0.0 };
        let adaptive = super::Options { noise: super::DEFAULT_NOISE, ..fixed };
        let (_, all) = solved.render_gather(&cam, &fixed, &tracer, &indirect, &crate::NoProgress);
        let (img, sampled) = solved.render_gather(&cam, &adaptive, &tracer, &indirect, &crate::NoProgress);
        let worst = img.pixels.iter().map(|p| ((p.max_element() - 2.0) / 2.0).abs()).fold(0.0, f64::max);
        assert!(worst < 2e-3, "worst pixel {worst:e} from L = 2");
        let (rays, all_rays) = (sampled.rays, all.rays);
        assert_eq!((sampled.pixels, all.pixels), (24 * 24, 24 * 24));
        assert_eq!(sampled.positions_per_pixel(), super::ADAPTIVE_FIRST as f64);
        assert_eq!(all.positions_per_pixel(), 36.0);
        // 8 of 36 positions per pixel.
        let share = rays as f64 / all_rays as f64;
        assert!((share - 8.0 / 36.0).abs() < 0.02, "{rays} of {all_rays} rays: {share}");
    }

    /// In the furnace (closed room, ρ = 0.5, every surface emitting radiance Ke = 1, so
    /// E = π) every visible point shows L = B/π = E/((1 − ρ)π) = 2: every gather ray meets
    /// the same reflected radiosity B − E = π, and the interpolated path reads the same
    /// irradiance. Both ways of reading the indirect light must reproduce it to the
    /// solver's tolerance (a ray lost, a wrong element or a unit slip would show).
    #[test]
    fn both_indirect_paths_are_exact_in_the_furnace() {
        let (solved, tracer) = furnace();
        let cam = solved.scene.camera.unwrap();
        let b = solved.solution.display_radiosity();
        let (lo, hi) = b.iter().fold((f64::MAX, 0f64), |(l, h), x| (l.min(x.min_element()), h.max(x.max_element())));
        let expect = 0.5 * (lo + hi) / std::f64::consts::PI;
        assert!((hi - lo) / hi < 1e-3, "furnace solution spread {lo}..{hi}");
        for (gathered, axis) in [(true, 1), (true, 3), (false, 0)] {
            let opts = super::Options { width: 24, height: 24, spp_axis: 2, shadow_axis: 1, gather_axis: axis, seed: 3, noise: 0.0 };
            let indirect = solved.indirect(gathered);
            let (img, sampled) = solved.render_gather(&cam, &opts, &tracer, &indirect, &crate::NoProgress);
            let rays = sampled.rays;
            let worst = img.pixels.iter().map(|p| ((p.max_element() - expect) / expect).abs()).fold(0.0, f64::max);
            eprintln!("gathered {gathered} ×{axis}: worst pixel {worst:e}");
            assert!(worst < 2e-3, "gathered {gathered} ×{axis}: worst pixel {worst:e} from L = {expect}");
            if gathered {
                // One camera ray, one shadow ray per emitter and axis² gather rays per
                // position: the gather rays were cast.
                assert!(rays >= (24 * 24 * 4 * (1 + axis * axis)) as u64, "{rays} rays");
            }
        }
    }
}
