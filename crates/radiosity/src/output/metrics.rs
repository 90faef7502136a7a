//! Image error metrics (definition in `../shared/reference/README.md`).
//!
//! Relative RMSE: `sqrt(mean over pixels and channels of (I − R)²) / mean(R)`.
//! Light-masked: exclude every pixel whose reference has a channel above 1.0 (the light)
//! and the 1-pixel ring around them.

use crate::render::Image;
use crate::{Error, Result};

/// Pixels kept by the light mask (true = used).
pub fn light_mask(reference: &Image, threshold: f64) -> Vec<bool> {
    let (w, h) = (reference.width, reference.height);
    let bright: Vec<bool> = reference.pixels.iter().map(|p| p.max_element() > threshold).collect();
    let mut keep = vec![true; w * h];
    for y in 0..h {
        for x in 0..w {
            if bright[y * w + x] {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                        if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                            keep[yy as usize * w + xx as usize] = false;
                        }
                    }
                }
            }
        }
    }
    keep
}

/// Relative RMSE of `img` against `reference` over the pixels where `mask` is true
/// (all pixels if None).
pub fn relative_rmse(img: &Image, reference: &Image, mask: Option<&[bool]>) -> Result<f64> {
    if img.width != reference.width || img.height != reference.height {
        return Err(Error::Invalid(format!(
            "image sizes differ: {}x{} vs reference {}x{}",
            img.width, img.height, reference.width, reference.height
        )));
    }
    let mut se = 0.0;
    let mut sum = 0.0;
    let mut count = 0usize;
    for (k, (a, r)) in img.pixels.iter().zip(&reference.pixels).enumerate() {
        if mask.is_some_and(|m| !m[k]) {
            continue;
        }
        let d = *a - *r;
        se += d.dot(d);
        sum += r.x + r.y + r.z;
        count += 3;
    }
    if count == 0 || sum <= 0.0 {
        return Err(Error::Invalid("the reference image is black where compared".into()));
    }
    let n = count as f64;
    Ok((se / n).sqrt() / (sum / n))
}

/// Light-masked relative RMSE (threshold 1.0).
pub fn relative_rmse_light_masked(img: &Image, reference: &Image) -> Result<f64> {
    let mask = light_mask(reference, 1.0);
    relative_rmse(img, reference, Some(&mask))
}

/// A heat map of the per-pixel error |I − R| / mean(R), as PNG bytes: black = 0,
/// through red and yellow to white at ≥ 50 % of the mean.
pub fn heatmap_png(img: &Image, reference: &Image) -> Result<Vec<u8>> {
    if img.width != reference.width || img.height != reference.height {
        return Err(Error::Invalid("image sizes differ".into()));
    }
    let mean = reference.pixels.iter().map(|p| p.x + p.y + p.z).sum::<f64>() / (3 * reference.pixels.len()).max(1) as f64;
    let mut rgb = Vec::with_capacity(img.pixels.len() * 3);
    for (a, r) in img.pixels.iter().zip(&reference.pixels) {
        let e = ((*a - *r).abs().max_element() / mean.max(f64::MIN_POSITIVE) / 0.5).clamp(0.0, 1.0);
        let (cr, cg, cb) = (3.0 * e, 3.0 * e - 1.0, 3.0 * e - 2.0);
        for c in [cr, cg, cb] {
            rgb.push((c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
        }
    }
    super::png::encode_rgb8(img.width, img.height, &rgb)
}
