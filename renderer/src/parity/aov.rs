//! Mitsuba's `depth` and `aov` integrators: what the camera ray meets first — its distance,
//! position, normals, texture coordinates and their derivatives, the material's diffuse
//! reflectance, the primitive and shape it belongs to — as image channels (arbitrary output
//! variables), and the coverage of the images of the integrators an `aov` integrator nests.
//!
//! Channels are named as Mitsuba's film names them: `<name>.<suffix>` for a variable
//! `<name>:<kind>` of `aovs` (suffixes in [`AovKind::suffixes`]). Every value is the mean over
//! the pixel's samples (weighted by the reconstruction filter, as the images are), zero where
//! the ray meets nothing.

use crate::description::{AovKind, AovSpec};
use crate::film::render_pixels_channels;
use crate::integrators::RayIntegrator;
use crate::lights::Light;
use crate::math::Ray;
use crate::sampling::{rng_for, Pcg32, UniformSource};
use crate::scene::{Scene, SurfaceInteraction};
use crate::spectrum::Rgb;
use glam::{UVec2, Vec2, Vec3};
use indicatif::ProgressBar;

/// Mitsuba's `depth` integrator: the distance along the camera ray to the first surface (every
/// colour channel), zero where the ray escapes.
#[derive(Debug, Clone, Copy, Default)]
pub struct DepthIntegrator;

impl RayIntegrator for DepthIntegrator {
    #[inline]
    fn li(&self, scene: &Scene, ray: Ray, _rng: &mut Pcg32) -> Rgb {
        scene
            .intersect(&ray)
            .map_or(Rgb::ZERO, |si| Rgb::splat(si.t))
    }

    fn identity(&self) -> serde_json::Value {
        serde_json::json!({ "integrator": "depth" })
    }
}

/// The random-stream pass of the variables' samples: their own streams, apart from pass 0 of
/// the nested integrators' images.
const AOV_STREAM_PASS: u64 = 1;

/// The channel names of `aovs`, in order (`dd.y:depth` → `dd.y.T`).
pub fn aov_channel_names(aovs: &[AovSpec]) -> Vec<String> {
    aovs.iter()
        .flat_map(|a| {
            a.kind
                .suffixes()
                .iter()
                .map(move |s| format!("{}.{s}", a.name))
        })
        .collect()
}

/// The variables of an image and the coverage of its nested images, per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct AovImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Channel names ([`aov_channel_names`]).
    pub channels: Vec<String>,
    /// One plane per channel, rows top to bottom.
    pub planes: Vec<Vec<f32>>,
    /// The share of camera samples that meet a surface (filter-weighted): the alpha
    /// (`<name>.A`) of nested `direct` and `depth` images, and of `path` and `volpath` ones
    /// unless [`environment_seen`].
    pub hits: Vec<f32>,
    /// The mean filter weight of the samples (1 for the box filter): the alpha of nested `path`
    /// and `volpath` images when [`environment_seen`] — every ray finds light.
    pub weights: Vec<f32>,
}

/// Whether the camera sees something in every direction: an environment light (`constant` or
/// `envmap`, not a directional one) that `hide_emitters` does not hide. Mitsuba's `path` and
/// `volpath` then report every sample as valid.
pub fn environment_seen(scene: &Scene) -> bool {
    !scene.hide_emitters()
        && scene
            .lights
            .iter()
            .any(|l| matches!(l, Light::Constant(_) | Light::Envmap(_)))
}

/// Renders the variables `aovs` with `spp` camera samples per pixel from the streams of `seed`
/// (in the current rayon pool; bit-identical for any thread count). Ray differentials are
/// scaled by 1/√spp, as Mitsuba scales them, for `duv_dx` and `duv_dy`.
pub fn render_aovs(
    scene: &Scene,
    aovs: &[AovSpec],
    spp: u32,
    seed: u64,
    progress: Option<&ProgressBar>,
) -> AovImage {
    let res = scene.camera.resolution();
    let channels = aov_channel_names(aovs);
    let values = channels.len();
    let differential_scale = 1.0 / (spp.max(1) as f32).sqrt();
    // Per pixel: the variables, then the hits and the weights.
    let planes = render_pixels_channels(
        res.x,
        res.y,
        values + 2,
        progress,
        spp as u64,
        |x, y, out| {
            let mut rng = rng_for(seed, AOV_STREAM_PASS, y as u64 * res.x as u64 + x as u64);
            let mut sample = vec![0.0f32; values];
            for _ in 0..spp {
                let u_film = rng.next_2d();
                let u_lens = rng.next_2d();
                let (position, weight) =
                    scene.camera.filter().sample(UVec2::new(x, y), res, u_film);
                let ray = scene.camera.ray_at(position, u_lens);
                let si = scene.intersect(&ray);
                sample.fill(0.0);
                if let Some(si) = &si {
                    let differentials = || {
                        scene
                            .camera
                            .ray_differentials(position, u_lens)
                            .map(|r| scale_differential(&ray, &r, differential_scale))
                    };
                    write_values(scene, aovs, si, differentials, &mut sample);
                }
                for (o, v) in out.iter_mut().zip(&sample) {
                    *o += v * weight;
                }
                if si.is_some() {
                    out[values] += weight;
                }
                out[values + 1] += weight;
            }
            let n = spp.max(1) as f32;
            for o in out.iter_mut() {
                *o /= n;
            }
        },
    );
    let mut planes = planes;
    let weights = planes.pop().unwrap_or_default();
    let hits = planes.pop().unwrap_or_default();
    AovImage {
        width: res.x,
        height: res.y,
        channels,
        planes,
        hits,
        weights,
    }
}

/// Mitsuba's `RayDifferential::scale_differential`: the offset ray moved towards the main ray,
/// origin and direction alike, to `scale` of its offset.
fn scale_differential(ray: &Ray, offset: &Ray, scale: f32) -> Ray {
    Ray {
        o: ray.o + (offset.o - ray.o) * scale,
        d: ray.d + (offset.d - ray.d) * scale,
        ..*ray
    }
}

/// The variables at the hit `si` of a camera ray, in channel order, into `out`;
/// `differentials` gives the (scaled) rays one pixel right and one pixel down.
fn write_values(
    scene: &Scene,
    aovs: &[AovSpec],
    si: &SurfaceInteraction,
    differentials: impl Fn() -> [Ray; 2],
    out: &mut [f32],
) {
    let mut k = 0;
    let mut put = |values: &[f32]| {
        out[k..k + values.len()].copy_from_slice(values);
        k += values.len();
    };
    // ∂uv/∂x and ∂uv/∂y, traced once if either is asked for.
    let mut partials = None;
    let mut uv_partials_once =
        || *partials.get_or_insert_with(|| uv_partials(si, &differentials()));
    for aov in aovs {
        match aov.kind {
            AovKind::Albedo => {
                let wo = si.frame.to_local(si.wo);
                let albedo = scene.bsdf(si).diffuse_reflectance(wo, &si.shading_point());
                put(&albedo.to_array());
            }
            AovKind::Depth => put(&[si.t]),
            AovKind::Position => put(&si.p.to_array()),
            AovKind::Uv => put(&si.uv.to_array()),
            AovKind::GeometricNormal => put(&si.ng.to_array()),
            AovKind::ShadingNormal => put(&si.frame.n.to_array()),
            AovKind::DpDu => put(&si.dpdu.to_array()),
            AovKind::DpDv => put(&si.dpdv.to_array()),
            AovKind::DuvDx => put(&uv_partials_once()[0].to_array()),
            AovKind::DuvDy => put(&uv_partials_once()[1].to_array()),
            AovKind::PrimIndex => put(&[si.prim as f32]),
            AovKind::ShapeIndex => put(&[(si.shape + 1) as f32]),
        }
    }
}

/// ∂uv/∂x and ∂uv/∂y at `si` (Mitsuba's `compute_uv_partials`): where the offset rays meet the
/// hit's tangent plane, expressed in ∂p/∂u and ∂p/∂v by least squares; zero where those are
/// degenerate.
fn uv_partials(si: &SurfaceInteraction, offsets: &[Ray; 2]) -> [Vec2; 2] {
    let n = si.ng;
    let d = n.dot(si.p);
    let dp = offsets.map(|r| {
        let t = (d - n.dot(r.o)) / n.dot(r.d);
        r.o + r.d * t - si.p
    });
    let (a00, a01, a11) = (
        si.dpdu.dot(si.dpdu),
        si.dpdu.dot(si.dpdv),
        si.dpdv.dot(si.dpdv),
    );
    let inv_det = 1.0 / (a00 * a11 - a01 * a01);
    let inv_det = if inv_det.is_finite() { inv_det } else { 0.0 };
    dp.map(|dp: Vec3| {
        let (b0, b1) = (si.dpdu.dot(dp), si.dpdv.dot(dp));
        Vec2::new(a11 * b0 - a01 * b1, a00 * b1 - a01 * b0) * inv_det
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(name: &str, kind: AovKind) -> AovSpec {
        AovSpec {
            name: name.into(),
            kind,
        }
    }

    #[test]
    fn channel_names_follow_mitsubas_film() {
        let aovs = [
            spec("dd.y", AovKind::Depth),
            spec("nn", AovKind::ShadingNormal),
            spec("alb", AovKind::Albedo),
            spec("u", AovKind::Uv),
            spec("pi", AovKind::PrimIndex),
        ];
        assert_eq!(
            aov_channel_names(&aovs),
            ["dd.y.T", "nn.X", "nn.Y", "nn.Z", "alb.R", "alb.G", "alb.B", "u.U", "u.V", "pi.I"]
        );
    }

    #[test]
    fn uv_partials_of_a_plane_are_the_pixel_footprint_in_uv() {
        // A plane z = 0 with u = x/2, v = y/4 (dp/du = (2,0,0), dp/dv = (0,4,0)); offset rays
        // hit it 0.1 further along x and 0.3 further along y.
        let si = SurfaceInteraction {
            p: Vec3::new(1.0, 1.0, 0.0),
            ng: Vec3::Z,
            dpdu: Vec3::new(2.0, 0.0, 0.0),
            dpdv: Vec3::new(0.0, 4.0, 0.0),
            ..test_interaction()
        };
        let towards = |target: Vec3| {
            let o = Vec3::new(1.0, 1.0, 5.0);
            Ray {
                o,
                d: (target - o).normalize(),
                tmin: 0.0,
                tmax: f32::INFINITY,
            }
        };
        let rays = [
            towards(Vec3::new(1.1, 1.0, 0.0)),
            towards(Vec3::new(1.0, 1.3, 0.0)),
        ];
        let [dx, dy] = uv_partials(&si, &rays);
        assert!(
            (dx - Vec2::new(0.05, 0.0)).abs().max_element() < 1e-5,
            "{dx}"
        );
        assert!(
            (dy - Vec2::new(0.0, 0.075)).abs().max_element() < 1e-5,
            "{dy}"
        );
        // Degenerate parametrisation: zero, not NaN.
        let flat = SurfaceInteraction {
            dpdu: Vec3::ZERO,
            ..si
        };
        assert_eq!(uv_partials(&flat, &rays), [Vec2::ZERO; 2]);
    }

    /// A hit with every field set to something harmless.
    fn test_interaction() -> SurfaceInteraction {
        SurfaceInteraction {
            p: Vec3::ZERO,
            t: 1.0,
            ng: Vec3::Z,
            frame: crate::frame::Frame::from_normal(Vec3::Z),
            uv: Vec2::ZERO,
            dpdu: Vec3::X,
            dpdv: Vec3::Y,
            wo: Vec3::Z,
            shape: 0,
            prim: 0,
            bary: Vec2::ZERO,
            material: 0,
            light: None,
        }
    }

    #[test]
    fn scaled_differentials_move_towards_the_main_ray() {
        let ray = Ray {
            o: Vec3::ZERO,
            d: Vec3::Z,
            tmin: 0.0,
            tmax: 7.0,
        };
        let offset = Ray {
            o: Vec3::new(2.0, 0.0, 0.0),
            d: Vec3::new(0.0, 1.0, 1.0),
            tmin: 0.0,
            tmax: 1.0,
        };
        let r = scale_differential(&ray, &offset, 0.25);
        assert_eq!(r.o, Vec3::new(0.5, 0.0, 0.0));
        assert_eq!(r.d, Vec3::new(0.0, 0.25, 1.0));
        assert_eq!(r.tmax, 7.0);
    }
}
