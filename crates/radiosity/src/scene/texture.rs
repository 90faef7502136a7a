//! Textures: images that vary a material's reflectance (glTF `baseColorTexture`, MTL
//! `map_Kd`) or emitted radiance (`emissiveTexture`, `map_Ke`) over its surfaces.
//!
//! **Colour.** 8- and 16-bit PNG and JPEG texels are sRGB-encoded colours (glTF says so for
//! base colour and emissive textures, and MTL files in practice mean the same); they are
//! decoded to linear values once, at load, with the sRGB transfer function (IEC 61966-2-1).
//! Alpha is ignored (surfaces are opaque).
//!
//! **Where a surface point reads its texel.** Each polygon carries, per texture-coordinate
//! set, an affine map from its plane to (u, v) ([`UvMap`], exact for triangles, a
//! least-squares fit for larger polygons), so that every later stage — meshing, clipping,
//! back sides, the final gather, lightmap texels — finds a point's texture coordinates from
//! its position alone. A [`TextureRef`] then applies `KHR_texture_transform`
//! (`uv' = T·R·S·uv`) and the sampler's wrap modes; u runs right and v down the image, as in
//! glTF (OBJ's `vt`, which runs up, is flipped when read).
//!
//! **Integrals.** The radiosity system needs one reflectance per element, and energy is
//! right only if it is the texture's mean over the element's footprint (the texture times
//! the factor, integrated over the element, divided by its area). [`Texture::mean_over`]
//! integrates exactly: the element's image in texture space is clipped against every texel
//! it touches (box reconstruction), at the finest mip level where it covers at most
//! [`MEAN_TEXELS`] texels (mip levels are box means, so a checkerboard under a large element
//! gives its mean, and a small element its own texels). Lightmaps then keep the detail the elements
//! average away: the final gather multiplies the irradiance at each pixel or texel by the
//! texel under it ([`super::Scene::reflectance_at`]).

use std::io::Cursor;

use glam::{DVec2, DVec3};

use crate::Rgb;

/// Largest texture side accepted, in texels (larger images are refused, not decoded).
pub const MAX_TEXTURE_SIDE: u32 = 16_384;

/// Bytes a decoder may allocate for one image.
const MAX_DECODE_BYTES: u64 = 1 << 30;

/// How texture coordinates outside [0, 1] are brought back into the image (glTF sampler
/// `wrapS`/`wrapT`; MTL textures repeat).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// The image tiles the plane (glTF 10497, the default).
    #[default]
    Repeat,
    /// The edge texels continue outwards (glTF 33071).
    ClampToEdge,
    /// Every other tile is mirrored (glTF 33648).
    MirroredRepeat,
}

impl Wrap {
    /// From a glTF sampler's wrap code (None for an unknown code).
    pub fn from_gltf(code: u32) -> Option<Wrap> {
        match code {
            10497 => Some(Wrap::Repeat),
            33071 => Some(Wrap::ClampToEdge),
            33648 => Some(Wrap::MirroredRepeat),
            _ => None,
        }
    }

    /// Texel index `i` in `0..n` for an index anywhere.
    #[inline]
    fn index(self, i: i64, n: usize) -> usize {
        let n = n as i64;
        (match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m >= n {
                    2 * n - 1 - m
                } else {
                    m
                }
            }
        }) as usize
    }
}

/// One use of a texture by a material: which image, which texture-coordinate set, the
/// `KHR_texture_transform` and the sampler's wrap modes.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into the scene's textures.
    pub texture: u32,
    /// Texture-coordinate set (glTF `TEXCOORD_n`; OBJ has only set 0).
    pub tex_coord: u32,
    /// Affine map applied to (u, v) before the lookup, as two rows `[a, b, c]`:
    /// `u' = a·u + b·v + c` (identity when there is no transform).
    pub transform: [[f64; 3]; 2],
    /// Wrap modes along u and v.
    pub wrap: [Wrap; 2],
}

impl TextureRef {
    /// Texture `texture` on coordinate set `tex_coord`, repeating, untransformed.
    pub fn new(texture: u32, tex_coord: u32) -> Self {
        TextureRef { texture, tex_coord, transform: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], wrap: [Wrap::Repeat; 2] }
    }

    /// The transform of `KHR_texture_transform`: `T(offset)·R(rotation)·S(scale)`, with the
    /// rotation turning (u, v) counter-clockwise in the image (v down) by `rotation` radians.
    pub fn with_transform(mut self, offset: [f64; 2], rotation: f64, scale: [f64; 2]) -> Self {
        let (s, c) = rotation.sin_cos();
        self.transform = [[c * scale[0], s * scale[1], offset[0]], [-s * scale[0], c * scale[1], offset[1]]];
        self
    }

    /// (u, v) after the transform.
    #[inline]
    pub fn apply(&self, uv: DVec2) -> DVec2 {
        let [a, b] = &self.transform;
        DVec2::new(a[0] * uv.x + a[1] * uv.y + a[2], b[0] * uv.x + b[1] * uv.y + b[2])
    }

    /// Factor by which the transform scales areas in (u, v).
    fn area_scale(&self) -> f64 {
        let [a, b] = &self.transform;
        (a[0] * b[1] - a[1] * b[0]).abs()
    }
}

/// An affine map from points of a polygon's plane to texture coordinates:
/// `uv(x) = uv0 + (grad_u·(x − origin), grad_v·(x − origin))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvMap {
    /// A point of the plane.
    pub origin: DVec3,
    /// Texture coordinates at `origin`.
    pub uv0: DVec2,
    /// Gradient of u along the plane.
    pub grad_u: DVec3,
    /// Gradient of v along the plane.
    pub grad_v: DVec3,
}

impl UvMap {
    /// The map that takes each vertex to its coordinates: exact for a triangle, the
    /// least-squares affine fit for more vertices (exact when the file's mapping is affine,
    /// as for a rectangle textured by its corners). Degenerate input gives the constant map
    /// of the mean coordinates.
    pub fn fit(vertices: &[DVec3], uvs: &[DVec2]) -> UvMap {
        let n = vertices.len().min(uvs.len());
        let c = vertices[..n].iter().copied().sum::<DVec3>() / n.max(1) as f64;
        let uc = uvs[..n].iter().copied().sum::<DVec2>() / n.max(1) as f64;
        let constant = UvMap { origin: c, uv0: uc, grad_u: DVec3::ZERO, grad_v: DVec3::ZERO };
        let normal = crate::geom::newell_normal(&vertices[..n]);
        if n < 3 || !(normal.length() > 0.0) || !uc.is_finite() {
            return constant;
        }
        let nz = normal.normalize();
        let t1 = nz.any_orthonormal_vector();
        let t2 = nz.cross(t1);
        // Normal equations of uv − uc = M·(a, b), (a, b) the in-plane coordinates.
        let (mut saa, mut sab, mut sbb) = (0.0, 0.0, 0.0);
        let (mut sua, mut sub, mut sva, mut svb) = (0.0, 0.0, 0.0, 0.0);
        for (p, uv) in vertices[..n].iter().zip(&uvs[..n]) {
            let d = *p - c;
            let (a, b) = (d.dot(t1), d.dot(t2));
            let w = *uv - uc;
            saa += a * a;
            sab += a * b;
            sbb += b * b;
            sua += w.x * a;
            sub += w.x * b;
            sva += w.y * a;
            svb += w.y * b;
        }
        let det = saa * sbb - sab * sab;
        if !(det > 1e-300) || det <= 1e-12 * (saa * sbb) {
            return constant;
        }
        let solve = |ra: f64, rb: f64| ((ra * sbb - rb * sab) / det, (rb * saa - ra * sab) / det);
        let (ua, ub) = solve(sua, sub);
        let (va, vb) = solve(sva, svb);
        let map = UvMap { origin: c, uv0: uc, grad_u: ua * t1 + ub * t2, grad_v: va * t1 + vb * t2 };
        if map.grad_u.is_finite() && map.grad_v.is_finite() {
            map
        } else {
            constant
        }
    }

    /// Texture coordinates at a point of the plane.
    #[inline]
    pub fn at(&self, x: DVec3) -> DVec2 {
        let d = x - self.origin;
        self.uv0 + DVec2::new(self.grad_u.dot(d), self.grad_v.dot(d))
    }

    /// Area in (u, v) of one unit of area of the plane.
    pub fn area_scale(&self) -> f64 {
        self.grad_u.cross(self.grad_v).length()
    }
}

/// One level of the mip pyramid.
#[derive(Clone, Debug, PartialEq)]
struct Level {
    width: usize,
    height: usize,
    texels: Vec<[f32; 3]>,
}

impl Level {
    #[inline]
    fn texel(&self, x: i64, y: i64, wrap: [Wrap; 2]) -> DVec3 {
        let t = self.texels[wrap[1].index(y, self.height) * self.width + wrap[0].index(x, self.width)];
        DVec3::new(t[0] as f64, t[1] as f64, t[2] as f64)
    }

    /// Bilinear lookup at (u, v) (texel centres at half-integers).
    fn bilinear(&self, uv: DVec2, wrap: [Wrap; 2]) -> DVec3 {
        let x = uv.x * self.width as f64 - 0.5;
        let y = uv.y * self.height as f64 - 0.5;
        if !(x.is_finite() && y.is_finite()) || x.abs() > 1e15 || y.abs() > 1e15 {
            return self.texel(0, 0, wrap);
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0, wrap) * (1.0 - fx) + self.texel(x0 + 1, y0, wrap) * fx;
        let b = self.texel(x0, y0 + 1, wrap) * (1.0 - fx) + self.texel(x0 + 1, y0 + 1, wrap) * fx;
        a * (1.0 - fy) + b * fy
    }

    /// The next coarser level: 2 × 2 box means (an odd last row or column averages what
    /// it has).
    fn half(&self) -> Level {
        let (w, h) = (self.width.div_ceil(2).max(1), self.height.div_ceil(2).max(1));
        let mut texels = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0f64; 3];
                let mut k = 0.0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = (2 * x + dx, 2 * y + dy);
                    if sx < self.width && sy < self.height {
                        let t = self.texels[sy * self.width + sx];
                        for c in 0..3 {
                            acc[c] += t[c] as f64;
                        }
                        k += 1.0;
                    }
                }
                texels.push(acc.map(|a| (a / k) as f32));
            }
        }
        Level { width: w, height: h, texels }
    }
}

/// A decoded texture: linear RGB texels and their mip pyramid.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Where it came from (file name, glTF image), for messages.
    pub name: String,
    /// Mean texel over the whole image (linear).
    pub mean: Rgb,
    /// Largest texel value per channel (linear).
    pub max: Rgb,
    levels: Vec<Level>,
}

/// The first RGB(A) layer of an OpenEXR file's bytes: width, height and linear RGB texels,
/// row-major from the top-left.
pub fn decode_exr_rgb(bytes: &[u8]) -> Result<(usize, usize, Vec<[f32; 3]>), String> {
    use exr::prelude::*;
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |res: Vec2<usize>, _| (res.width(), res.height(), vec![[0f32; 3]; res.width() * res.height()]),
            |img: &mut (usize, usize, Vec<[f32; 3]>), pos: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                let w = img.0;
                img.2[pos.y() * w + pos.x()] = [r, g, b];
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| format!("cannot read EXR: {e}"))?;
    Ok(img.layer_data.channel_data.pixels)
}

/// sRGB-encoded value in [0, 1] to linear (IEC 61966-2-1).
#[inline]
pub fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

impl Texture {
    /// A texture from linear texels, row-major from the top-left.
    pub fn from_linear(name: &str, width: usize, height: usize, texels: Vec<[f32; 3]>) -> Result<Texture, String> {
        if width == 0 || height == 0 || texels.len() != width * height {
            return Err(format!("{width} × {height} texels do not match {} values", texels.len()));
        }
        if texels.iter().any(|t| t.iter().any(|c| !c.is_finite() || *c < 0.0)) {
            return Err("a texel is negative or not finite".into());
        }
        let mut levels = vec![Level { width, height, texels }];
        while levels.last().is_some_and(|l| l.width > 1 || l.height > 1) {
            let next = levels.last().map(Level::half).unwrap_or_else(|| unreachable!());
            levels.push(next);
        }
        let top = &levels[0].texels;
        let n = top.len() as f64;
        let mut sum = DVec3::ZERO;
        let mut max = DVec3::ZERO;
        for t in top {
            let v = DVec3::new(t[0] as f64, t[1] as f64, t[2] as f64);
            sum += v;
            max = max.max(v);
        }
        Ok(Texture { name: name.to_string(), mean: sum / n, max, levels })
    }

    /// Decodes a PNG or JPEG image (format from its first bytes) holding sRGB colours.
    /// Errors say what is wrong, without the name (callers place it).
    pub fn decode(name: &str, bytes: &[u8]) -> Result<Texture, String> {
        let reader = image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| format!("cannot read the image: {e}"))?;
        let Some(format) = reader.format() else {
            return Err("is not a PNG or JPEG image (unrecognised first bytes)".into());
        };
        if !matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
            return Err(format!("is a {format:?} image; PNG and JPEG textures are read"));
        }
        let mut reader = reader;
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_TEXTURE_SIDE);
        limits.max_image_height = Some(MAX_TEXTURE_SIDE);
        limits.max_alloc = Some(MAX_DECODE_BYTES);
        reader.limits(limits);
        let img = reader.decode().map_err(|e| format!("cannot decode the {format:?} image: {e}"))?;
        let (w, h) = (img.width() as usize, img.height() as usize);
        let texels: Vec<[f32; 3]> = match img {
            image::DynamicImage::ImageRgb8(_)
            | image::DynamicImage::ImageRgba8(_)
            | image::DynamicImage::ImageLuma8(_)
            | image::DynamicImage::ImageLumaA8(_) => {
                let lut: Vec<f32> = (0..256).map(|i| srgb_to_linear(i as f64 / 255.0) as f32).collect();
                img.to_rgb8().pixels().map(|p| p.0.map(|c| lut[c as usize])).collect()
            }
            _ => img.to_rgb16().pixels().map(|p| p.0.map(|c| srgb_to_linear(c as f64 / 65535.0) as f32)).collect(),
        };
        Texture::from_linear(name, w, h, texels)
    }

    /// An environment image (see [`super::Environment`]): OpenEXR (its first RGB(A)
    /// layer) or Radiance `.hdr` as linear radiance, PNG or JPEG as sRGB like any texture.
    /// Errors for a non-finite or negative texel.
    pub fn decode_environment(name: &str, bytes: &[u8]) -> Result<Texture, String> {
        let (w, h, texels): (usize, usize, Vec<[f32; 3]>) = if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
            decode_exr_rgb(bytes)?
        } else if bytes.starts_with(b"#?") {
            let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Hdr)
                .map_err(|e| format!("cannot read Radiance HDR: {e}"))?
                .to_rgb32f();
            let (w, h) = (img.width() as usize, img.height() as usize);
            (w, h, img.pixels().map(|p| p.0).collect())
        } else {
            return Texture::decode(name, bytes);
        };
        if let Some(k) = texels.iter().position(|t| t.iter().any(|c| !(c.is_finite() && *c >= 0.0))) {
            return Err(format!("texel ({}, {}) is {:?}: radiance must be finite and non-negative", k % w.max(1), k / w.max(1), texels[k]));
        }
        Texture::from_linear(name, w, h, texels)
    }

    /// Width and height of the image, in texels.
    pub fn size(&self) -> (usize, usize) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// The full-resolution texels (linear RGB, row-major from the top-left).
    pub fn texels(&self) -> &[[f32; 3]] {
        &self.levels[0].texels
    }

    /// Bytes held (all levels).
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.texels.len() * 12).sum()
    }

    /// Linear value at `uv` (after the reference's transform) read from mip level `lod`
    /// (0 = full resolution; fractional levels blend the two nearest, trilinear).
    pub fn sample(&self, tref: &TextureRef, uv: DVec2, lod: f64) -> Rgb {
        let uv = tref.apply(uv);
        let top = (self.levels.len() - 1) as f64;
        let lod = if lod.is_finite() { lod.clamp(0.0, top) } else { 0.0 };
        let l0 = lod.floor() as usize;
        let f = lod - l0 as f64;
        let a = self.levels[l0].bilinear(uv, tref.wrap);
        if f > 1e-6 && l0 + 1 < self.levels.len() {
            a * (1.0 - f) + self.levels[l0 + 1].bilinear(uv, tref.wrap) * f
        } else {
            a
        }
    }

    /// Mip level whose texels cover `uv_area` (area in (u, v) after the transform) each.
    fn lod_for(&self, uv_area: f64) -> f64 {
        let (w, h) = self.size();
        let texels = uv_area * (w * h) as f64;
        if texels > 1.0 {
            0.5 * texels.log2()
        } else {
            0.0
        }
    }

    /// Value at point `x` of a polygon mapped by `map`, filtered over a footprint of
    /// `footprint_area` (scene units², 0 for the finest level).
    pub fn at_point(&self, tref: &TextureRef, map: &UvMap, x: DVec3, footprint_area: f64) -> Rgb {
        let lod = self.lod_for(footprint_area * map.area_scale() * tref.area_scale());
        self.sample(tref, map.at(x), lod)
    }

    /// Mean over a convex polygon (`corners`, in the plane of `map`): the exact integral of
    /// the texels (box reconstruction) over the polygon's image in texture space, divided by
    /// its area. The texels are read at the finest mip level where the polygon covers at
    /// most [`MEAN_TEXELS`] of them (mip levels are box means, so the integral stays right
    /// away from the polygon's border).
    pub fn mean_over(&self, tref: &TextureRef, map: &UvMap, corners: &[DVec3]) -> Rgb {
        let (w, h) = self.size();
        let mut pts = [DVec2::ZERO; MAX_CLIP];
        let n = corners.len().min(MAX_CLIP - 4);
        for (q, c) in pts.iter_mut().zip(&corners[..n]) {
            let t = tref.apply(map.at(*c));
            *q = DVec2::new(t.x * w as f64, t.y * h as f64);
        }
        let area = polygon_area(&pts[..n]).abs();
        let finite = pts[..n].iter().all(|p| p.is_finite() && p.abs().max_element() < 1e12);
        if !(area > 1e-9) || !finite {
            let c = corners[..n].iter().copied().sum::<DVec3>() / n.max(1) as f64;
            return self.sample(tref, map.at(c), 0.0);
        }
        let (lo, hi) = pts[..n].iter().fold((pts[0], pts[0]), |(l, u), p| (l.min(*p), u.max(*p)));
        let mut level = 0;
        loop {
            let k = (1u64 << (2 * level)) as f64;
            let bbox = (hi - lo).x.max(1.0) * (hi - lo).y.max(1.0) / k;
            if level + 1 >= self.levels.len() || (area / k <= MEAN_TEXELS && bbox <= 64.0 * MEAN_TEXELS) {
                break;
            }
            level += 1;
        }
        let lv = &self.levels[level];
        let sx = lv.width as f64 / w as f64;
        let sy = lv.height as f64 / h as f64;
        for p in &mut pts[..n] {
            *p = DVec2::new(p.x * sx, p.y * sy);
        }
        let (lo, hi) = (DVec2::new(lo.x * sx, lo.y * sy), DVec2::new(hi.x * sx, hi.y * sy));
        let mut acc = DVec3::ZERO;
        let mut total = 0.0;
        let mut row = [DVec2::ZERO; MAX_CLIP];
        let mut cell = [DVec2::ZERO; MAX_CLIP];
        let mut tmp = [DVec2::ZERO; MAX_CLIP];
        for y in lo.y.floor() as i64..hi.y.ceil() as i64 {
            let (y0, y1) = (y as f64, (y + 1) as f64);
            let m = clip(&pts[..n], &mut tmp, 1, y0, true);
            let m = clip(&tmp[..m], &mut row, 1, y1, false);
            if m < 3 {
                continue;
            }
            let (rlo, rhi) = row[..m].iter().fold((f64::MAX, f64::MIN), |(l, u), p| (l.min(p.x), u.max(p.x)));
            for x in rlo.floor() as i64..rhi.ceil() as i64 {
                let k = clip(&row[..m], &mut tmp, 0, x as f64, true);
                let k = clip(&tmp[..k], &mut cell, 0, (x + 1) as f64, false);
                if k < 3 {
                    continue;
                }
                let a = polygon_area(&cell[..k]).abs();
                acc += lv.texel(x, y, tref.wrap) * a;
                total += a;
            }
        }
        if total > 0.0 {
            acc / total
        } else {
            self.sample(tref, map.at(corners[0]), 0.0)
        }
    }
}

/// Most texels [`Texture::mean_over`] integrates over (it reads a coarser mip level beyond).
pub const MEAN_TEXELS: f64 = 256.0;

/// Most vertices of a polygon while it is clipped to a texel (4 corners + 4 cuts).
const MAX_CLIP: usize = 12;

/// Signed area of a polygon in the plane (shoelace).
fn polygon_area(p: &[DVec2]) -> f64 {
    let n = p.len();
    0.5 * (0..n).map(|i| p[i].perp_dot(p[(i + 1) % n])).sum::<f64>()
}

/// Clips a convex polygon to the half-plane `coord[axis] ≥ at` (`keep_above`) or `≤ at`
/// (Sutherland–Hodgman); returns the vertex count written to `out`.
fn clip(poly: &[DVec2], out: &mut [DVec2; MAX_CLIP], axis: usize, at: f64, keep_above: bool) -> usize {
    let inside = |p: &DVec2| if keep_above { p[axis] >= at } else { p[axis] <= at };
    let mut k = 0;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        let (ia, ib) = (inside(&a), inside(&b));
        if ia && k < MAX_CLIP {
            out[k] = a;
            k += 1;
        }
        if ia != ib && k < MAX_CLIP {
            let t = (at - a[axis]) / (b[axis] - a[axis]);
            out[k] = a + (b - a) * t;
            k += 1;
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(n: usize, a: f32, b: f32) -> Texture {
        let texels = (0..n * n).map(|i| if (i % n + i / n) % 2 == 0 { [a; 3] } else { [b; 3] }).collect();
        Texture::from_linear("checker", n, n, texels).unwrap()
    }

    #[test]
    fn srgb_decoding_matches_the_standard() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-12);
        // 0.5 encodes 0.21404 (IEC 61966-2-1).
        assert!((srgb_to_linear(0.5) - 0.214_041_140).abs() < 1e-8);
    }

    #[test]
    fn wrap_modes_fold_indices() {
        assert_eq!(Wrap::Repeat.index(-1, 4), 3);
        assert_eq!(Wrap::Repeat.index(9, 4), 1);
        assert_eq!(Wrap::ClampToEdge.index(-3, 4), 0);
        assert_eq!(Wrap::ClampToEdge.index(7, 4), 3);
        assert_eq!(Wrap::MirroredRepeat.index(4, 4), 3);
        assert_eq!(Wrap::MirroredRepeat.index(-1, 4), 0);
        assert_eq!(Wrap::MirroredRepeat.index(8, 4), 0);
    }

    #[test]
    fn uv_map_is_exact_on_triangles_and_affine_quads() {
        let v = [
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(2.0, 0.0, 1.0),
            DVec3::new(2.0, 3.0, 1.0),
            DVec3::new(0.0, 3.0, 1.0),
        ];
        let uv = [DVec2::new(0.0, 1.0), DVec2::new(1.0, 1.0), DVec2::new(1.0, 0.0), DVec2::new(0.0, 0.0)];
        for m in [UvMap::fit(&v[..3], &uv[..3]), UvMap::fit(&v, &uv)] {
            for (p, t) in v.iter().zip(&uv) {
                assert!((m.at(*p) - *t).length() < 1e-12, "{:?} vs {t:?}", m.at(*p));
            }
            assert!((m.area_scale() - 1.0 / 6.0).abs() < 1e-12);
        }
    }

    #[test]
    fn mean_over_a_large_footprint_is_the_checker_mean() {
        let t = checker(64, 0.9, 0.1);
        assert!((t.mean - DVec3::splat(0.5)).abs().max_element() < 1e-6);
        // A square of side 1 mapped to 3.3 × 3.3 repeats of the texture.
        let v = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        let uv = v.map(|p| DVec2::new(p.x, p.y) * 3.3);
        let m = UvMap::fit(&v, &uv);
        let r = TextureRef::new(0, 0);
        let mean = t.mean_over(&r, &m, &v);
        assert!((mean - DVec3::splat(0.5)).abs().max_element() < 0.01, "{mean}");
        // One texel's footprint gives that texel: the first one (top-left) is 0.9.
        let small = [DVec3::ZERO, DVec3::new(0.001, 0.0, 0.0), DVec3::new(0.001, 0.001, 0.0)];
        let uv1 = small.map(|p| DVec2::new(p.x, p.y) * 10.0);
        let m1 = UvMap::fit(&small, &uv1);
        let one = t.mean_over(&r, &m1, &small);
        assert!((one - DVec3::splat(0.9)).abs().max_element() < 1e-6, "{one}");
    }

    #[test]
    fn transform_offsets_rotates_and_scales() {
        let r = TextureRef::new(0, 0).with_transform([0.5, 0.25], std::f64::consts::FRAC_PI_2, [2.0, 1.0]);
        // S: (1, 0) -> (2, 0); R: (2, 0) -> (0, -2); T: -> (0.5, -1.75).
        let p = r.apply(DVec2::new(1.0, 0.0));
        assert!((p - DVec2::new(0.5, -1.75)).length() < 1e-12, "{p:?}");
    }
}
