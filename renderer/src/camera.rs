//! Perspective, thin-lens and orthographic cameras with Mitsuba 3's conventions: the camera looks along its
//! local +z, local +y is up and local +x points to the image's LEFT (Mitsuba's `lookat` builds
//! x = up × dir); pixel (0, 0) is the top-left corner of the image.

use crate::description::{CameraDesc, FovAxis, Projection};
use crate::filter::PixelFilter;
use crate::math::Ray;
use crate::sampling::square_to_uniform_disk_concentric;
use glam::{Mat4, UVec2, Vec2, Vec3};

/// A pinhole or thin-lens camera ready to generate rays.
#[derive(Debug, Clone)]
pub struct Camera {
    /// Camera-to-world transform.
    to_world: Mat4,
    /// Perspective or orthographic.
    projection: Projection,
    /// 1 / aspect ratio: the half height of an orthographic view (its half width is 1).
    inv_aspect: f32,
    /// Origin of the camera in world space.
    position: Vec3,
    /// tan(horizontal fov / 2).
    tan_half_x: f32,
    /// tan(horizontal fov / 2) / aspect: the vertical extent of the image plane at z = 1.
    tan_half_y: f32,
    /// Near clip distance (along local z).
    near_clip: f32,
    /// Far clip distance (along local z).
    far_clip: f32,
    /// Lens radius (0 = pinhole).
    aperture_radius: f32,
    /// Distance of the plane in focus (along local z).
    focus_distance: f32,
    /// Size of the rendered image in pixels: the film's crop window (the whole film without one).
    resolution: UVec2,
    /// Film size in pixels (the projection spans it, whatever the crop).
    film_size: Vec2,
    /// Top-left pixel of the crop window on the film.
    crop_offset: Vec2,
    /// The principal point's offset from the film centre, in fractions of the film size.
    principal_point: Vec2,
    /// The film's reconstruction filter, which places each pixel's samples.
    filter: PixelFilter,
}

/// A primary ray and the weight its radiance enters the pixel with (1 unless the
/// reconstruction filter has negative lobes).
#[derive(Debug, Clone, Copy)]
pub struct CameraSample {
    /// The ray.
    pub ray: Ray,
    /// The filter weight of the sample.
    pub weight: f32,
}

/// Mitsuba's `parse_fov`: the horizontal field of view (degrees) for a given fov and axis.
pub fn horizontal_fov(fov: f32, axis: FovAxis, aspect: f32) -> f32 {
    let fov = fov as f64;
    let aspect = aspect as f64;
    let axis = match axis {
        FovAxis::Smaller => {
            if aspect > 1.0 {
                FovAxis::Y
            } else {
                FovAxis::X
            }
        }
        FovAxis::Larger => {
            if aspect > 1.0 {
                FovAxis::X
            } else {
                FovAxis::Y
            }
        }
        a => a,
    };
    let half = (0.5 * fov).to_radians();
    let x = match axis {
        FovAxis::Y => 2.0 * (half.tan() * aspect).atan(),
        FovAxis::Diagonal => {
            let diagonal = 2.0 * half.tan();
            let width = diagonal / (1.0 + 1.0 / (aspect * aspect)).sqrt();
            2.0 * (0.5 * width).atan()
        }
        _ => 2.0 * half,
    };
    x.to_degrees() as f32
}

/// Mitsuba's `lookat` transform: camera-to-world with local +z towards `target`, local +x =
/// up × dir (the image's left) and local +y the re-orthogonalised up vector.
pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let dir = (target - origin).normalize();
    let left = up.normalize().cross(dir).normalize();
    let new_up = dir.cross(left);
    Mat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        origin.extend(1.0),
    )
}

impl Camera {
    /// Builds the camera from its description.
    pub fn new(desc: &CameraDesc) -> Self {
        let aspect = desc.width as f32 / desc.height as f32;
        let x_fov = horizontal_fov(desc.fov, desc.fov_axis, aspect);
        let tan_half_x = (0.5 * x_fov).to_radians().tan();
        Camera {
            to_world: desc.to_world,
            projection: desc.projection,
            inv_aspect: 1.0 / aspect,
            position: desc.to_world.transform_point3(Vec3::ZERO),
            tan_half_x,
            tan_half_y: tan_half_x / aspect,
            near_clip: desc.near_clip,
            far_clip: desc.far_clip,
            aperture_radius: desc.aperture_radius,
            focus_distance: desc.focus_distance,
            resolution: desc
                .crop
                .map_or(UVec2::new(desc.width, desc.height), |c| c.size),
            film_size: Vec2::new(desc.width as f32, desc.height as f32),
            crop_offset: desc.crop.map_or(Vec2::ZERO, |c| c.offset.as_vec2()),
            principal_point: desc.principal_point,
            filter: PixelFilter::new(desc.filter, desc.sample_border),
        }
    }

    /// The film's reconstruction filter.
    pub fn filter(&self) -> &PixelFilter {
        &self.filter
    }

    /// A primary ray for `pixel`: its film position drawn from the reconstruction filter
    /// centred on the pixel with `u_film` ∈ [0,1)² (uniform in the pixel for the box filter),
    /// `u_lens` for the lens position of a thin-lens camera.
    #[inline]
    pub fn sample_ray(&self, pixel: UVec2, u_film: Vec2, u_lens: Vec2) -> CameraSample {
        let (position, weight) = self.filter.sample(pixel, self.resolution, u_film);
        CameraSample {
            ray: self.ray_at(position, u_lens),
            weight,
        }
    }

    /// Size of the rendered image in pixels: the film's crop window, or the whole film.
    pub fn resolution(&self) -> UVec2 {
        self.resolution
    }

    /// Camera position (lens centre) in world space.
    pub fn position(&self) -> Vec3 {
        self.position
    }

    /// Unit viewing direction (local +z) in world space.
    pub fn forward(&self) -> Vec3 {
        self.to_world.transform_vector3(Vec3::Z).normalize()
    }

    /// Distance of a point seen by a primary ray from the camera (G-buffer depth): from the
    /// lens centre for a perspective camera, from the image plane for an orthographic one.
    pub fn depth_of(&self, p: Vec3) -> f32 {
        match self.projection {
            Projection::Perspective => p.distance(self.position),
            Projection::Orthographic => (p - self.position).dot(self.forward()),
        }
    }

    /// The primary ray through `pixel` at sub-pixel offset `u_film` ∈ [0,1)² (the film
    /// position `pixel + u_film`, whatever the reconstruction filter), using `u_lens` for the
    /// lens position of a thin-lens camera (ignored by a pinhole). The direction is unit
    /// length; the ray starts on the near clip plane and ends on the far one, as in Mitsuba.
    #[inline]
    pub fn generate_ray(&self, pixel: UVec2, u_film: Vec2, u_lens: Vec2) -> Ray {
        self.ray_at(pixel.as_vec2() + u_film, u_lens)
    }

    /// The rays one pixel to the right and one pixel down of the ray through film `position`
    /// with lens sample `u_lens`, as Mitsuba's `sample_ray_differential` makes them: the same
    /// origin and the neighbouring pixel's direction for perspective and thin-lens cameras (the
    /// same lens point), the neighbouring origin and the same direction for orthographic ones.
    pub fn ray_differentials(&self, position: Vec2, u_lens: Vec2) -> [Ray; 2] {
        let ray = self.ray_at(position, u_lens);
        [Vec2::X, Vec2::Y].map(|offset| {
            let next = self.ray_at(position + offset, u_lens);
            if self.projection == Projection::Orthographic {
                Ray { d: ray.d, ..next }
            } else {
                Ray { o: ray.o, ..next }
            }
        })
    }

    /// The primary ray through film position `position` (pixels from the rendered image's
    /// top-left corner — the crop window's, if the film has one; it may lie outside the image),
    /// using `u_lens` as [`Camera::generate_ray`].
    #[inline]
    pub fn ray_at(&self, position: Vec2, u_lens: Vec2) -> Ray {
        // Relative film position; Mitsuba adds the principal point's offset here.
        let s = (position + self.crop_offset) / self.film_size + self.principal_point;
        if self.projection == Projection::Orthographic {
            // Parallel rays from the near plane of the view rectangle; the (scaled) to_world
            // sizes it, as in Mitsuba.
            let o = self.to_world.transform_point3(Vec3::new(
                1.0 - 2.0 * s.x,
                (1.0 - 2.0 * s.y) * self.inv_aspect,
                self.near_clip,
            ));
            let axis = self.to_world.transform_vector3(Vec3::Z);
            let d = axis.normalize();
            let scale = axis.length();
            return Ray {
                o,
                d,
                tmin: 0.0,
                tmax: (self.far_clip - self.near_clip) * scale,
            };
        }
        // Film x grows to the right, camera-space +x points left: hence 1 − 2s.
        let plane = Vec3::new(
            (1.0 - 2.0 * s.x) * self.tan_half_x,
            (1.0 - 2.0 * s.y) * self.tan_half_y,
            1.0,
        );
        let (o_local, d_local) = if self.aperture_radius > 0.0 {
            let lens = square_to_uniform_disk_concentric(u_lens) * self.aperture_radius;
            let lens = Vec3::new(lens.x, lens.y, 0.0);
            let focus = plane * self.focus_distance;
            (lens, (focus - lens).normalize())
        } else {
            (Vec3::ZERO, plane.normalize())
        };
        let inv_z = 1.0 / d_local.z;
        let near_t = self.near_clip * inv_z;
        let far_t = self.far_clip * inv_z;
        let o = self.to_world.transform_point3(o_local);
        let d = self.to_world.transform_vector3(d_local).normalize();
        Ray {
            o: o + d * near_t,
            d,
            tmin: 0.0,
            tmax: far_t - near_t,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn desc(w: u32, h: u32, fov: f32, axis: FovAxis) -> CameraDesc {
        CameraDesc {
            to_world: Mat4::IDENTITY,
            projection: crate::description::Projection::Perspective,
            fov,
            fov_axis: axis,
            near_clip: 0.01,
            far_clip: 1000.0,
            aperture_radius: 0.0,
            focus_distance: 1.0,
            width: w,
            height: h,
            filter: crate::filter::FilterDesc::Box,
            sample_border: false,
            crop: None,
            principal_point: glam::Vec2::ZERO,
        }
    }

    /// A cropped film renders the window's pixels with the rays the whole film gives them
    /// (bit for bit, with the box filter), and its image has the window's size.
    #[test]
    fn crop_window_renders_the_full_films_rays() {
        let full = Camera::new(&desc(40, 30, 50.0, FovAxis::X));
        let mut d = desc(40, 30, 50.0, FovAxis::X);
        d.crop = Some(crate::description::FilmCrop {
            offset: UVec2::new(7, 11),
            size: UVec2::new(16, 9),
        });
        let cropped = Camera::new(&d);
        assert_eq!(cropped.resolution(), UVec2::new(16, 9));
        for (x, y) in [(0, 0), (15, 8), (5, 3)] {
            for u in [Vec2::new(0.25, 0.75), Vec2::new(0.9, 0.1)] {
                let a = cropped.sample_ray(UVec2::new(x, y), u, Vec2::ZERO);
                let b = full.sample_ray(UVec2::new(x + 7, y + 11), u, Vec2::ZERO);
                assert_eq!((a.ray.o, a.ray.d, a.weight), (b.ray.o, b.ray.d, b.weight));
            }
        }
    }

    /// A principal point offset (dx, dy) moves the film position that looks straight ahead
    /// (along local +z) from the centre to ((½ − dx)·width, (½ − dy)·height), in pixels from
    /// the film's top-left corner (Mitsuba's sign convention).
    #[test]
    fn principal_point_offset_shifts_the_view() {
        let mut d = desc(40, 30, 50.0, FovAxis::X);
        d.principal_point = Vec2::new(0.1, -0.2);
        let cam = Camera::new(&d);
        let ahead = cam.ray_at(Vec2::new(20.0 - 4.0, 15.0 + 6.0), Vec2::ZERO);
        assert!((ahead.d - Vec3::Z).length() < 1e-6, "{}", ahead.d);
        // The offset is a shift of the image plane, not a rotation: directions elsewhere
        // differ from the centred camera's by the same film translation.
        let centred = Camera::new(&desc(40, 30, 50.0, FovAxis::X));
        let a = cam.ray_at(Vec2::new(3.0, 7.0), Vec2::ZERO);
        let b = centred.ray_at(Vec2::new(3.0 + 4.0, 7.0 - 6.0), Vec2::ZERO);
        assert!((a.d - b.d).length() < 1e-6);
    }

    /// Orthographic: parallel rays along the scaled local +z from a rectangle [−1, 1] ×
    /// [−1/aspect, 1/aspect] of the scaled frame (a 4×2 film, to_world scaling x and y by 3);
    /// the G-buffer depth is measured from the image plane.
    #[test]
    fn orthographic_rays_are_parallel_and_span_the_scaled_view() {
        let mut d = desc(4, 2, 45.0, FovAxis::X);
        d.projection = Projection::Orthographic;
        d.to_world = Mat4::from_translation(Vec3::new(0.0, 0.0, -5.0))
            * Mat4::from_scale(Vec3::new(3.0, 3.0, 1.0));
        let cam = Camera::new(&d);
        let left = cam.generate_ray(UVec2::new(0, 0), Vec2::new(0.0, 0.5), Vec2::ZERO);
        let right = cam.generate_ray(UVec2::new(3, 0), Vec2::new(1.0, 0.5), Vec2::ZERO);
        let top = cam.generate_ray(UVec2::new(2, 0), Vec2::ZERO, Vec2::ZERO);
        for r in [left, right, top] {
            assert!((r.d - Vec3::Z).length() < 1e-6, "{:?}", r.d);
        }
        // Local +x is the image's left (as the perspective camera): x = +3 … −3.
        assert!(
            (left.o - Vec3::new(3.0, 0.75, -5.0 + 0.01)).length() < 1e-5,
            "{:?}",
            left.o
        );
        assert!((right.o.x + 3.0).abs() < 1e-5);
        // The top edge: y = 3 · 1/aspect = 1.5.
        assert!((top.o.y - 1.5).abs() < 1e-5, "{:?}", top.o);
        assert!((cam.depth_of(Vec3::new(2.0, 1.0, 1.0)) - 6.0).abs() < 1e-5);
    }

    #[test]
    fn centre_ray_looks_along_z_and_edges_match_fov() {
        let cam = Camera::new(&desc(4, 2, 90.0, FovAxis::X));
        // Centre of the image: the shared corner of pixels (1,0)/(2,1) at offset (1,1) of pixel (1,0)... use
        // pixel (2,1) offset (0,0) which is the exact centre (2/4, 1/2).
        let r = cam.generate_ray(UVec2::new(2, 1), Vec2::ZERO, Vec2::ZERO);
        assert!((r.d - Vec3::Z).length() < 1e-6, "{:?}", r.d);
        assert!((r.o - Vec3::new(0.0, 0.0, 0.01)).length() < 1e-6);
        // Left edge of the image (s.x = 0, s.y = 0.5): 45° to camera +x (Mitsuba's left).
        let r = cam.generate_ray(UVec2::new(0, 1), Vec2::ZERO, Vec2::ZERO);
        let e = Vec3::new(1.0, 0.0, 1.0).normalize();
        assert!((r.d - e).length() < 1e-6, "{:?}", r.d);
        // Top-left corner: y = tan(45°)/aspect = 0.5, up is +y.
        let r = cam.generate_ray(UVec2::new(0, 0), Vec2::ZERO, Vec2::ZERO);
        let e = Vec3::new(1.0, 0.5, 1.0).normalize();
        assert!((r.d - e).length() < 1e-6, "{:?}", r.d);
    }

    #[test]
    fn fov_axes_follow_mitsuba() {
        // Vertical fov 90 on a 2:1 film: horizontal half-angle atan(2).
        let x = horizontal_fov(90.0, FovAxis::Y, 2.0);
        assert!((x - 2.0 * 2f32.atan().to_degrees()).abs() < 1e-4);
        assert_eq!(horizontal_fov(90.0, FovAxis::Smaller, 2.0), x);
        assert_eq!(horizontal_fov(90.0, FovAxis::Larger, 2.0), 90.0);
        // Diagonal of a square film: half-width = tan(45°)/√2.
        let d = horizontal_fov(90.0, FovAxis::Diagonal, 1.0);
        assert!((d - 2.0 * (1.0 / 2f32.sqrt()).atan().to_degrees()).abs() < 1e-4);
    }

    #[test]
    fn thin_lens_rays_converge_on_the_focus_plane() {
        let mut d = desc(8, 8, 40.0, FovAxis::X);
        d.aperture_radius = 0.2;
        d.focus_distance = 3.0;
        let cam = Camera::new(&d);
        let pix = UVec2::new(2, 5);
        let u = Vec2::new(0.3, 0.7);
        let hit = |r: Ray| r.at((3.0 - r.o.z) / r.d.z);
        let a = hit(cam.generate_ray(pix, u, Vec2::new(0.1, 0.9)));
        let b = hit(cam.generate_ray(pix, u, Vec2::new(0.8, 0.2)));
        assert!((a - b).length() < 1e-4, "{a:?} {b:?}");
    }
}
