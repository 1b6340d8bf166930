//! Area light (Mitsuba's `area`): radiance leaving the front side of a shape, a colour or a
//! texture over the shape's uvs. Next-event estimation samples a point uniformly by area on the
//! shape, on a mesh of three or more triangles within a triangle chosen by what it can deliver
//! to the shading point ([`EmitterTree`]), and a sphere seen from outside by the cone of
//! directions it subtends. (Mitsuba samples a textured radiance by the texture's distribution
//! over uv, which presumes uvs that cover the shape once: on a textured `cube` emitter Mitsuba
//! 3.9.1's NEE finds no light at all. By area is unbiased on any shape.)

use super::bounds::{bounding_sphere, LightBounds};
use super::channel_mean;
use super::emitter_tree::EmitterTree;
use super::{EmissionSample, LightSample};
use crate::frame::Frame;
use crate::math::{coordinate_system, spawn_ray};
use crate::sampling::{square_to_cosine_hemisphere, square_to_uniform_cone, uniform_cone_pdf};
use crate::shapes::{Shape, Sphere};
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Emission attached to a shape.
#[derive(Debug, Clone)]
pub struct AreaLight {
    /// Index of the shape in the scene.
    pub shape: u32,
    /// Emitted radiance (`radiance`), looked up at the surface's uv.
    pub radiance: Texture,
    /// How next-event estimation chooses the triangle of a mesh (`None`: by area).
    pub triangles: Option<Box<EmitterTree>>,
    /// Mitsuba's `directionalarea`: the radiance leaves only along the surface normal (a
    /// collimated beam). No ray from a point can meet that direction exactly, so `eval`,
    /// `sample_li` and `pdf_li` find nothing (as Mitsuba's do: its path tracer renders such a
    /// light black) and only photons carry it.
    pub collimated: bool,
}

impl AreaLight {
    /// Emission `radiance` on `shape`, the scene's shape number `index`, `collimated` for a
    /// `directionalarea`.
    pub fn new(index: u32, shape: &Shape, radiance: Texture, collimated: bool) -> Self {
        let triangles = match shape {
            Shape::Mesh(mesh) if !collimated => EmitterTree::triangles(mesh).map(Box::new),
            _ => None,
        };
        AreaLight {
            shape: index,
            radiance,
            triangles,
            collimated,
        }
    }

    /// Radiance leaving the surface with normal `n` at texture point `tp` in direction `w`
    /// (front side only).
    #[inline]
    pub fn eval(&self, n: Vec3, w: Vec3, tp: TexPoint) -> Rgb {
        if n.dot(w) > 0.0 && !self.collimated {
            self.radiance.eval(tp)
        } else {
            Rgb::ZERO
        }
    }

    /// Direct illumination at `p` on a surface with unit geometric normal `n` (`Vec3::ZERO`:
    /// none): for a sphere seen from outside, a direction uniform in the cone it subtends (as
    /// Mitsuba); otherwise a point sampled uniformly by area on `shape`, or on the triangle
    /// chosen for (`p`, `n`) by [`Self::triangles`].
    pub fn sample_li(
        &self,
        shape: &Shape,
        p: Vec3,
        n: Vec3,
        u_prim: f32,
        u: Vec2,
    ) -> Option<LightSample> {
        if self.collimated {
            return None;
        }
        if let Shape::Sphere(sphere) = shape {
            if let Some(cone) = SphereCone::new(sphere, p) {
                if sphere.flip_normals {
                    // Only the inner side emits: invisible from outside.
                    return None;
                }
                let local = square_to_uniform_cone(u, cone.cos_max);
                let wi = (cone.frame.to_world(local)).normalize();
                // Distance to the near intersection, from the triangle (p, centre, hit).
                let cos_t = local.z;
                let sin2 = (1.0 - cos_t * cos_t).max(0.0);
                let r2 = sphere.radius * sphere.radius;
                let dist = cone.dist * cos_t - (r2 - cone.dist * cone.dist * sin2).max(0.0).sqrt();
                let pdf = uniform_cone_pdf(cone.cos_max);
                let q = p + wi * dist;
                return Some(LightSample {
                    wi,
                    p: q,
                    dist,
                    weight: self.radiance.eval(sphere.uv_at(q)) / pdf,
                    pdf,
                    delta: false,
                    infinite: false,
                    light: 0,
                });
            }
        }
        let s = match (shape, &self.triangles) {
            (Shape::Mesh(mesh), Some(triangles)) => {
                let (tri, pmf, _) = triangles.sample(p, n, u_prim)?;
                mesh.sample_triangle(tri, u, pmf / triangles.weight(tri))
            }
            _ => shape.sample_area(u_prim, u),
        };
        let d = s.p - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = d / dist;
        let cos_l = -s.n.dot(wi);
        if cos_l <= 0.0 {
            return None;
        }
        let pdf = s.pdf * dist2 / cos_l;
        if !pdf.is_finite() || pdf <= 0.0 {
            return None;
        }
        Some(LightSample {
            wi,
            p: s.p,
            dist,
            weight: self.radiance.eval(s.tex()) / pdf,
            pdf,
            delta: false,
            infinite: false,
            light: 0,
        })
    }

    /// Solid-angle density of [`Self::sample_li`] from `p_ref` with geometric normal `n_ref`
    /// for the direction that reaches the light at `p_light` in triangle `prim` (meshes),
    /// where the light's normal is `n_light`.
    #[inline]
    pub fn pdf_li(
        &self,
        shape: &Shape,
        p_ref: Vec3,
        n_ref: Vec3,
        p_light: Vec3,
        n_light: Vec3,
        prim: u32,
    ) -> f32 {
        if self.collimated {
            return 0.0;
        }
        if let Shape::Sphere(sphere) = shape {
            if let Some(cone) = SphereCone::new(sphere, p_ref) {
                return if sphere.flip_normals {
                    0.0
                } else {
                    uniform_cone_pdf(cone.cos_max)
                };
            }
        }
        let d = p_light - p_ref;
        let dist2 = d.length_squared();
        let cos_l = -n_light.dot(d) / dist2.sqrt();
        if cos_l <= 0.0 {
            return 0.0;
        }
        match &self.triangles {
            Some(triangles) => {
                let area = triangles.weight(prim);
                if area > 0.0 {
                    dist2 / cos_l * (triangles.pmf(p_ref, n_ref, prim) / area)
                } else {
                    0.0
                }
            }
            None => dist2 / (cos_l * shape.area()),
        }
    }

    /// A photon from a uniform point, cosine-distributed over the front hemisphere: flux
    /// L(uv)·π / pdf (L·π·A for a uniform radiance); a collimated light's leaves along the
    /// normal with flux L(uv) / pdf (L·A: Mitsuba's `directionalarea` weighs its particles by
    /// the area, its "radiance" being a power per unit area).
    pub fn sample_emission(
        &self,
        shape: &Shape,
        u_prim: f32,
        u_pos: Vec2,
        u_dir: Vec2,
    ) -> EmissionSample {
        let s = shape.sample_area(u_prim, u_pos);
        if self.collimated {
            return EmissionSample {
                ray: spawn_ray(s.p, s.n, s.n),
                flux: self.radiance.eval(s.tex()) / s.pdf,
                light: 0,
            };
        }
        let local = square_to_cosine_hemisphere(u_dir);
        let (t, b) = coordinate_system(s.n);
        let d = (t * local.x + b * local.y + s.n * local.z).normalize();
        EmissionSample {
            ray: spawn_ray(s.p, s.n, d),
            flux: self.radiance.eval(s.tex()) * (PI / s.pdf),
            light: 0,
        }
    }

    /// Emission bounds for light selection: the shape's bounding sphere and cone of normals,
    /// each normal's emission falling off to zero at 90°. The intensity along the strongest
    /// direction is L·A for a flat emitter and L·A/4 for a sphere; in between by the spread of
    /// the normals.
    /// A collimated light's intensity is zero: NEE never samples it.
    pub fn bounds(&self, shape: &Shape) -> LightBounds {
        let (lo, hi) = shape.bounds();
        let (center, radius) = bounding_sphere(lo, hi);
        let (axis, cos_o) = shape.normal_cone();
        let intensity = if self.collimated {
            0.0
        } else {
            channel_mean(self.radiance.mean()) * shape.area() * cos_o.max(0.25)
        };
        if cos_o <= -1.0 {
            LightBounds::omnidirectional(center, radius, intensity)
        } else {
            LightBounds::cone(center, radius, intensity, axis, cos_o, 0.0)
        }
    }

    /// Power L·π·A (L·A when collimated), with a texture's mean over its texels for L (light
    /// selection only needs a proportion; called once, when the scene is built).
    pub fn power(&self, shape: &Shape) -> Rgb {
        let solid = if self.collimated { 1.0 } else { PI };
        self.radiance.mean() * (solid * shape.area())
    }
}

/// The cone of directions a sphere subtends from an outside point.
struct SphereCone {
    /// Frame whose +z points from the reference point to the centre.
    frame: Frame,
    /// Distance from the reference point to the centre.
    dist: f32,
    /// Cosine of the cone's half-angle.
    cos_max: f32,
}

impl SphereCone {
    /// The cone seen from `p`, or `None` when `p` is inside (or on) the sphere.
    fn new(sphere: &Sphere, p: Vec3) -> Option<Self> {
        let d = sphere.center - p;
        let dist = d.length();
        // A small margin: points on the surface itself sample by area.
        if dist <= sphere.radius * (1.0 + 1e-4) {
            return None;
        }
        let sin_max = sphere.radius / dist;
        let cos_max = (1.0 - sin_max * sin_max).max(0.0).sqrt();
        Some(SphereCone {
            frame: Frame::from_normal(d / dist),
            dist,
            cos_max,
        })
    }
}
