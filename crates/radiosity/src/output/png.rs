//! PNG encoding (8-bit sRGB).

use crate::render::Image;
use crate::{Error, Result};

/// Encodes 8-bit sRGB-encoded RGB pixels.
pub fn encode_rgb8(width: usize, height: usize, rgb: &[u8]) -> Result<Vec<u8>> {
    encode_rgb8_as(width, height, rgb, true)
}

/// Encodes 8-bit RGB pixels, marked sRGB or (`srgb` false) linear (gAMA 1.0): data such
/// as a `MOZ_lightmap`, which viewers read without a transfer function.
pub fn encode_rgb8_as(width: usize, height: usize, rgb: &[u8], srgb: bool) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width as u32, height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        if srgb {
            enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        } else {
            enc.set_source_gamma(png::ScaledFloat::new(1.0));
        }
        // fdeflate: several times faster than the default level for ~10 % larger files,
        // which matters when every view or frame is written.
        enc.set_compression(png::Compression::Fast);
        let mut w = enc.write_header().map_err(|e| Error::Invalid(format!("PNG encoding: {e}")))?;
        w.write_image_data(rgb).map_err(|e| Error::Invalid(format!("PNG encoding: {e}")))?;
    }
    Ok(out)
}

/// Encodes a radiance image: `exposure` scale (None = automatic), clip, sRGB.
pub fn encode(img: &Image, exposure: Option<f64>) -> Result<Vec<u8>> {
    let s = exposure.unwrap_or_else(|| super::auto_exposure(img));
    encode_rgb8(img.width, img.height, &super::to_srgb8(img, s))
}
