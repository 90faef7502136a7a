//! OpenEXR: linear radiance, 32-bit float RGB.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::*;

use crate::render::Image as RadianceImage;
use crate::{Error, Location, Result, Rgb};

/// Encodes `img` as an RGB float EXR file (uncompressed... ZIP compressed lines).
pub fn encode(img: &RadianceImage) -> Result<Vec<u8>> {
    let (w, h) = (img.width, img.height);
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let p = img.pixels[y * w + x];
        (p.x as f32, p.y as f32, p.z as f32)
    });
    let mut layer = Layer::new((w, h), LayerAttributes::named("radiance"), Encoding::SMALL_LOSSLESS, channels);
    layer.attributes.comments = Some(Text::from("linear radiance L = B/pi (radiosity renderer)"));
    let image = exr::image::Image::from_layer(layer);
    let mut buf = Cursor::new(Vec::new());
    image.write().non_parallel().to_buffered(&mut buf).map_err(|e| Error::Invalid(format!("EXR encoding: {e}")))?;
    Ok(buf.into_inner())
}

/// Decodes the first RGB(A) layer of an EXR file's bytes; `name` is used in errors.
pub fn decode(bytes: &[u8], name: &Path) -> Result<RadianceImage> {
    let (w, h, texels) =
        crate::scene::texture::decode_exr_rgb(bytes).map_err(|e| Error::input(Location::file(name), e))?;
    let mut img = RadianceImage::new(w, h);
    for (p, t) in img.pixels.iter_mut().zip(texels) {
        *p = Rgb::new(t[0] as f64, t[1] as f64, t[2] as f64);
    }
    Ok(img)
}

/// Reads an EXR file.
pub fn read(path: &Path) -> Result<RadianceImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode(&bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_is_exact_in_f32() {
        let mut img = RadianceImage::new(7, 5);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = Rgb::new(i as f64 * 0.25, 1.0 / (i + 1) as f64, 17.0);
        }
        let bytes = encode(&img).unwrap();
        let back = decode(&bytes, Path::new("x.exr")).unwrap();
        assert_eq!((back.width, back.height), (7, 5));
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            assert!((*a - *b).abs().max_element() <= 1e-6 * a.abs().max_element().max(1.0));
        }
    }
}
