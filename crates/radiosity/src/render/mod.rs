//! Stage 7: rendering — the solved scene seen through a pinhole camera.
//!
//! Images hold linear radiance `L = B/π` per pixel (diffuse surfaces), averaged over the
//! pixel's footprint (box filter, `spp × spp` stratified samples); back faces of one-sided
//! surfaces and empty background are black. Tone mapping is left to [`crate::output`].
//!
//! - [`gouraud`]: radiosity interpolated from the vertices (bilinear on quads,
//!   barycentric on triangles), or flat per element — the instant preview.
//! - [`gather`]: final gather — direct light exact per pixel, indirect light from the
//!   solution — for images that match a path tracer.

pub mod camera;
pub mod gather;
pub mod gouraud;
pub mod raster;

pub use camera::PinholeCamera;

use crate::Rgb;

/// A linear-radiance image; pixel (0,0) is top-left, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Radiance per pixel, row-major.
    pub pixels: Vec<Rgb>,
}

impl Image {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Image { width, height, pixels: vec![Rgb::ZERO; width * height] }
    }
    /// Pixel at column x, row y.
    pub fn at(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }
}
