//! Stage 8: output — the only place where linear radiance becomes display values.
//!
//! - [`png`]: exposure (automatic: 0.8 / 97th percentile of luminance, as the reference
//!   images' previews) times radiance, clipped, sRGB transfer function, 8-bit PNG.
//! - [`exr`]: linear radiance as 32-bit float OpenEXR (and reading EXR for comparisons).
//! - [`gltf`]: the solved mesh with its light baked into per-vertex `COLOR_0`, as GLB.
//! - [`metrics`]: relative RMSE between images, with the light-masked variant defined in
//!   `../shared/reference/README.md`.
//!
//! Encoders return bytes; writing files (atomically) is the caller's business, so the
//! library has no file-system side effects.

pub mod exr;
pub mod gltf;
pub mod matrix;
pub mod metrics;
pub mod png;

use crate::render::Image;
use crate::{luminance, Rgb};

/// The automatic exposure scale: 0.8 / p97(luminance) over the non-black pixels.
pub fn auto_exposure(img: &Image) -> f64 {
    let mut lum: Vec<f64> = img.pixels.iter().map(|p| luminance(*p)).filter(|l| *l > 0.0 && l.is_finite()).collect();
    if lum.is_empty() {
        return 1.0;
    }
    let k = ((lum.len() as f64 * 0.97) as usize).min(lum.len() - 1);
    let (_, p97, _) = lum.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    0.8 / *p97
}

/// The sRGB transfer function (IEC 61966-2-1) of a linear value in [0, 1].
#[inline]
pub fn srgb_oetf(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// 8-bit sRGB pixels (RGB, row-major) of `img` scaled by `exposure`.
pub fn to_srgb8(img: &Image, exposure: f64) -> Vec<u8> {
    let mut out = Vec::with_capacity(img.pixels.len() * 3);
    for p in &img.pixels {
        let c: Rgb = *p * exposure;
        for v in c.to_array() {
            out.push((srgb_oetf(v) * 255.0 + 0.5) as u8);
        }
    }
    out
}
