//! [`Camera`]: a look-at camera, orthographic or perspective, and the projection to pixels.

use crate::math::{Quat, Vec2, Vec3};

/// A look-at camera.
///
/// The camera sits at `eye`, looks at `target`, and turns so that `up` points up on screen
/// (only the part of `up` perpendicular to the viewing direction matters). With
/// `fov_y_deg == 0` it is **orthographic** and the image shows a slab `ortho_height` world
/// units tall (the width follows the image's aspect ratio); with `fov_y_deg > 0` it is a
/// **perspective** pinhole with that vertical field of view, and `ortho_height` only serves as
/// the reference for fixed point sizes (see [`super::RenderOptions::point_size_px`]).
///
/// Degenerate set-ups do not panic: an `eye` equal to `target` looks along −Z, an `up` parallel
/// to the viewing direction is replaced by some perpendicular, and a non-positive
/// `ortho_height` counts as 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Position of the camera (for an orthographic camera: a point on the far side of the
    /// near plane; only points in front of it are drawn).
    pub eye: Vec3,
    /// The point at the centre of the image.
    pub target: Vec3,
    /// The world direction that appears upwards on screen.
    pub up: Vec3,
    /// Vertical field of view in degrees; 0 means orthographic.
    pub fov_y_deg: f32,
    /// Height of the visible slab in world units (orthographic), and the reference height for
    /// fixed point sizes (both kinds).
    pub ortho_height: f32,
}

/// Extra room left around a framed box: the box fills 1 / `FRAME_MARGIN` of the view.
pub const FRAME_MARGIN: f32 = 1.08;

impl Camera {
    /// An orthographic camera that frames the box `aabb_min`..`aabb_max` seen along
    /// `view_dir`, with `up` up on screen, in a **square** picture (the box's larger projected
    /// extent fits, with a margin of [`FRAME_MARGIN`]); see [`Camera::frame_aspect`] for other
    /// aspect ratios.
    ///
    /// The bundled statues have +Y up and face +Z, so a statue seen from the front is
    /// `Camera::frame(min, max, -Vec3::Z, Vec3::Y)` ([`Camera::front`]).
    pub fn frame(aabb_min: Vec3, aabb_max: Vec3, view_dir: Vec3, up: Vec3) -> Camera {
        Camera::frame_aspect(aabb_min, aabb_max, view_dir, up, 1.0)
    }

    /// [`Camera::frame`] for a picture `aspect` = width / height: the projected box fits both
    /// the height and the width, with a margin of [`FRAME_MARGIN`].
    pub fn frame_aspect(
        aabb_min: Vec3,
        aabb_max: Vec3,
        view_dir: Vec3,
        up: Vec3,
        aspect: f32,
    ) -> Camera {
        Camera::frame_fov(aabb_min, aabb_max, view_dir, up, aspect, 0.0)
    }

    /// [`Camera::frame_aspect`] with a vertical field of view of `fov_y_deg` (0: orthographic,
    /// clamped to 170°).
    ///
    /// The target is the box's centre. Orthographic: the eye is four box diagonals back along
    /// `-view_dir`, so every point of the box is in front of the camera (also after
    /// [`Camera::orbit`]). Perspective: the eye is at the smallest distance at which all eight
    /// corners of the box fit in the picture with the margin (nearer corners look larger, so
    /// this is farther than the distance at which the target plane alone would fit), and
    /// `ortho_height` is the height the picture shows in the plane through the target. A box
    /// with non-finite or inverted corners is treated as the unit cube around the origin; a
    /// flat box is framed by its diagonal, a single point by a view 1 unit tall.
    pub fn frame_fov(
        aabb_min: Vec3,
        aabb_max: Vec3,
        view_dir: Vec3,
        up: Vec3,
        aspect: f32,
        fov_y_deg: f32,
    ) -> Camera {
        let (lo, hi) =
            if aabb_min.is_finite() && aabb_max.is_finite() && aabb_min.cmple(aabb_max).all() {
                (aabb_min, aabb_max)
            } else {
                (Vec3::splat(-0.5), Vec3::splat(0.5))
            };
        let (fwd, right, cam_up) = basis(view_dir, up);
        let center = (lo + hi) * 0.5;
        let half = (hi - lo) * 0.5;
        // Half extents of the box projected on the screen axes.
        let half_w = half.x * right.x.abs() + half.y * right.y.abs() + half.z * right.z.abs();
        let half_h = half.x * cam_up.x.abs() + half.y * cam_up.y.abs() + half.z * cam_up.z.abs();
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect
        } else {
            1.0
        };
        let radius = half.length();
        let mut height = 2.0 * half_h.max(half_w / aspect) * FRAME_MARGIN;
        if !(height > radius * 1e-6) {
            height = if radius > 0.0 { radius * 2.0 } else { 1.0 };
        }
        let fov = if fov_y_deg.is_finite() {
            fov_y_deg.clamp(0.0, 170.0)
        } else {
            0.0
        };
        if fov == 0.0 {
            let distance = 4.0 * radius.max(height);
            return Camera {
                eye: center - fwd * distance,
                target: center,
                up: cam_up,
                fov_y_deg: 0.0,
                ortho_height: height,
            };
        }
        let tan = (0.5 * fov.to_radians()).tan();
        // Every corner (x right, y up, z along the view from the centre) must satisfy
        // |y| · margin ≤ (distance + z) · tan and |x| · margin ≤ (distance + z) · tan · aspect.
        let mut distance = 0.5 * height / tan;
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 { -half.x } else { half.x },
                if i & 2 == 0 { -half.y } else { half.y },
                if i & 4 == 0 { -half.z } else { half.z },
            );
            let (x, y, z) = (corner.dot(right), corner.dot(cam_up), corner.dot(fwd));
            let need = (y.abs() / tan).max(x.abs() / (tan * aspect)) * FRAME_MARGIN - z;
            distance = distance.max(need);
        }
        // Keep the whole box in front of the eye.
        distance = distance.max(1.01 * radius);
        Camera {
            eye: center - fwd * distance,
            target: center,
            up: cam_up,
            fov_y_deg: fov,
            ortho_height: 2.0 * distance * tan,
        }
    }

    /// The front view of a statue in the data set's convention (+Y up, facing +Z): the box seen
    /// along −Z in a picture of aspect ratio `aspect` = width / height.
    pub fn front(aabb_min: Vec3, aabb_max: Vec3, aspect: f32) -> Camera {
        Camera::frame_aspect(aabb_min, aabb_max, -Vec3::Z, Vec3::Y, aspect)
    }

    /// The same view as a perspective camera with a vertical field of view of `fov_y_deg`
    /// (0 gives back an orthographic camera): the eye moves along the viewing axis to the
    /// distance at which the plane through the target still shows `ortho_height`. Parts of
    /// the object nearer than the target then look larger and may leave the picture; use
    /// [`Camera::frame_fov`] to frame a box in perspective.
    pub fn with_fov(self, fov_y_deg: f32) -> Camera {
        let fov = if fov_y_deg.is_finite() {
            fov_y_deg.clamp(0.0, 170.0)
        } else {
            0.0
        };
        if fov == 0.0 {
            return Camera {
                fov_y_deg: 0.0,
                ..self
            };
        }
        let (fwd, _, _) = basis(self.target - self.eye, self.up);
        let distance = 0.5 * self.height() / (0.5 * fov.to_radians()).tan();
        Camera {
            eye: self.target - fwd * distance,
            fov_y_deg: fov,
            ..self
        }
    }

    /// The camera turned by `angle_rad` around the vertical axis through the target (the axis
    /// along `up`), counter-clockwise seen from above (right-handed about `up`): frame `k` of
    /// a turntable film of `n` frames is `camera.orbit(k as f32 * TAU / n as f32)`.
    pub fn orbit(&self, angle_rad: f32) -> Camera {
        let axis = self.up.normalize_or(Vec3::Y);
        let rot = Quat::from_axis_angle(axis, angle_rad);
        Camera {
            eye: self.target + rot * (self.eye - self.target),
            ..*self
        }
    }

    /// Whether this is an orthographic camera (`fov_y_deg` is 0, negative or not a number).
    pub fn is_orthographic(&self) -> bool {
        !(self.fov_y_deg > 0.0)
    }

    /// `ortho_height`, or 1 when it is not a positive finite number.
    fn height(&self) -> f32 {
        if self.ortho_height.is_finite() && self.ortho_height > 0.0 {
            self.ortho_height
        } else {
            1.0
        }
    }

    /// Projects `p` into a `width` × `height` picture: `Some((pixel, depth))`, with the pixel
    /// position in continuous coordinates (pixel (`i`, `j`) covers `[i, i+1) × [j, j+1)`, y
    /// down) and the depth along the viewing direction, or `None` for a point behind the
    /// camera (or not finite). Points outside the picture are projected all the same.
    pub fn project(&self, p: Vec3, width: u32, height: u32) -> Option<(Vec2, f32)> {
        let view = View::new(self, width, height);
        let (s, depth) = view.project(p)?;
        Some((s, depth))
    }
}

/// Viewing direction, screen right and screen up for a view along `view_dir` with `up` up, all
/// unit and orthogonal, whatever the input.
pub(crate) fn basis(view_dir: Vec3, up: Vec3) -> (Vec3, Vec3, Vec3) {
    let fwd = view_dir.try_normalize().unwrap_or(-Vec3::Z);
    let right = fwd
        .cross(up)
        .try_normalize()
        .unwrap_or_else(|| fwd.any_orthonormal_vector());
    let cam_up = right.cross(fwd);
    (fwd, right, cam_up)
}

/// A camera prepared for one picture size: everything the per-point projection needs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct View {
    /// The camera's position.
    pub eye: Vec3,
    /// Unit viewing direction.
    pub fwd: Vec3,
    /// Unit screen right.
    pub right: Vec3,
    /// Unit screen up.
    pub up: Vec3,
    /// Orthographic (else perspective).
    pub ortho: bool,
    /// Pixels per world unit (orthographic) or the focal length in pixels (perspective).
    pub scale: f32,
    /// Distance from the eye to the target along the viewing direction.
    pub target_depth: f32,
    /// Smallest depth drawn.
    pub near: f32,
    /// Image centre in pixels: x, ...
    pub cx: f32,
    /// ... and y.
    pub cy: f32,
}

impl View {
    /// Prepares `camera` for a `width` × `height` picture.
    pub fn new(camera: &Camera, width: u32, height: u32) -> View {
        let (fwd, right, up) = basis(camera.target - camera.eye, camera.up);
        let ortho = camera.is_orthographic();
        let h = height as f32;
        let scale = if ortho {
            h / camera.height()
        } else {
            let fov = camera.fov_y_deg.min(170.0).to_radians();
            0.5 * h / (0.5 * fov).tan()
        };
        let target_depth = (camera.target - camera.eye).dot(fwd);
        let near = if ortho {
            0.0
        } else {
            (1e-4 * target_depth).max(f32::MIN_POSITIVE)
        };
        View {
            eye: camera.eye,
            fwd,
            right,
            up,
            ortho,
            scale,
            target_depth,
            near,
            cx: 0.5 * width as f32,
            cy: 0.5 * h,
        }
    }

    /// Pixels per world unit at `depth`.
    #[inline]
    pub fn pixels_per_unit(&self, depth: f32) -> f32 {
        if self.ortho {
            self.scale
        } else {
            self.scale / depth
        }
    }

    /// Camera-space coordinates (right, up, depth) of `p`.
    #[inline]
    pub fn camera_coords(&self, p: Vec3) -> Vec3 {
        let d = p - self.eye;
        Vec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.fwd))
    }

    /// Pixel position of camera-space point `c` (depth must be > 0 for perspective).
    #[inline]
    pub fn screen_coords(&self, c: Vec3) -> Vec2 {
        let k = self.pixels_per_unit(c.z);
        Vec2::new(self.cx + c.x * k, self.cy - c.y * k)
    }

    /// Pixel position and depth, or `None` behind the near plane or for non-finite input.
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<(Vec2, f32)> {
        let c = self.camera_coords(p);
        if !(c.z > self.near) || !c.is_finite() {
            return None;
        }
        let s = self.screen_coords(c);
        s.is_finite().then_some((s, c.z))
    }
}
