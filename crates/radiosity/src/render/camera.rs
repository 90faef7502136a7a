//! Pinhole camera rays (convention in [`crate::scene::camera`]).

use glam::DVec3;

use crate::scene::Camera;

/// A camera prepared for an image size.
#[derive(Clone, Copy, Debug)]
pub struct PinholeCamera {
    /// Eye position.
    pub eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    tan_half: f64,
    aspect: f64,
    width: f64,
    height: f64,
}

impl PinholeCamera {
    /// Prepares `cam` for a `width × height` image.
    pub fn new(cam: &Camera, width: usize, height: usize) -> Self {
        let forward = (cam.look_at - cam.position).normalize();
        let right = forward.cross(cam.up).normalize();
        let up = right.cross(forward);
        PinholeCamera {
            eye: cam.position,
            forward,
            right,
            up,
            tan_half: (0.5 * cam.vfov_deg.to_radians()).tan(),
            aspect: width as f64 / height as f64,
            width: width as f64,
            height: height as f64,
        }
    }

    /// Unnormalised direction through image position (x, y) in pixels (0,0 = top-left
    /// corner of the image; pixel centres at +0.5).
    #[inline]
    pub fn direction(&self, x: f64, y: f64) -> DVec3 {
        let sx = (2.0 * x / self.width - 1.0) * self.tan_half * self.aspect;
        let sy = (1.0 - 2.0 * y / self.height) * self.tan_half;
        self.forward + self.right * sx + self.up * sy
    }

    /// Angle a pixel spans at the image's centre, radians (small-angle).
    pub fn pixel_angle(&self) -> f64 {
        2.0 * self.tan_half / self.height
    }

    /// The camera frame (right, up, forward), orthonormal.
    pub fn frame(&self) -> (DVec3, DVec3, DVec3) {
        (self.right, self.up, self.forward)
    }

    /// Scale factors from camera-space slopes (x/z, y/z) to [-1, 1] screen coordinates.
    pub fn screen_scale(&self) -> (f64, f64) {
        (1.0 / (self.tan_half * self.aspect), 1.0 / self.tan_half)
    }

    /// Projects a world point to image coordinates (pixels), if it is in front.
    pub fn project(&self, p: DVec3) -> Option<(f64, f64)> {
        let d = p - self.eye;
        let z = d.dot(self.forward);
        if z <= 0.0 {
            return None;
        }
        let sx = d.dot(self.right) / z / (self.tan_half * self.aspect);
        let sy = d.dot(self.up) / z / self.tan_half;
        Some(((sx + 1.0) * 0.5 * self.width, (1.0 - sy) * 0.5 * self.height))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_right_is_forward_cross_up() {
        let cam = Camera { position: DVec3::ZERO, look_at: DVec3::Z, up: DVec3::Y, vfov_deg: 90.0 };
        let pc = PinholeCamera::new(&cam, 100, 100);
        // +X world appears on the left half of the image.
        let (x, y) = pc.project(DVec3::new(1.0, 0.0, 2.0)).unwrap();
        assert!(x < 50.0 && (y - 50.0).abs() < 1e-9);
        let d = pc.direction(x, y).normalize();
        assert!((d - DVec3::new(1.0, 0.0, 2.0).normalize()).length() < 1e-12);
        // Top row looks up.
        assert!(pc.direction(50.0, 0.0).y > 0.0);
    }
}
