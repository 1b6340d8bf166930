//! The renderable scene: shapes in a BVH, their materials and emission, the light list with
//! its selection (photons by power, NEE by power and by where the light comes from), the
//! camera, and the queries integrators make (closest hit, occlusion, emitted radiance, light
//! sampling for NEE and photon emission).

use crate::accel::{Accel, Bvh4Accel, PrimitiveHit};
use crate::bsdf::{Bsdf, ShadingPoint};
use crate::camera::Camera;
use crate::description::{EmitterDesc, Geometry, IntegratorDesc, SceneDescription};
use crate::frame::Frame;
use crate::lights::bounds::EmitterBounds;
use crate::lights::selection::LightSelection;
use crate::lights::{
    channel_mean, AreaLight, ConstantLight, DirectionalLight, EmissionSample, EnvmapLight, Light,
    LightSample, PhotonFocus, PointLight, ProjectorLight, SceneSphere, SpotLight,
};
use crate::math::{offset_point, spawn_ray, spawn_ray_to, Ray};
use crate::parity::media::{Medium, MediumInterface};
use crate::sampling::Distribution1D;
use crate::shapes::Shape;
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use anyhow::{bail, Result};
use glam::{Vec2, Vec3};

/// What [`Scene::intersect_emitter`] finds along a ray.
#[derive(Debug, Clone, Copy)]
pub enum EmitterHit {
    /// The closest hit is an emitting surface.
    Emitter(SurfaceInteraction),
    /// Nothing is hit and the scene has an environment light.
    Escaped,
    /// A non-emitting surface comes first, or nothing is hit and there is no environment.
    Blocked,
}

/// Everything known about a ray's closest hit.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceInteraction {
    /// Hit position.
    pub p: Vec3,
    /// Distance along the ray.
    pub t: f32,
    /// Unit geometric normal (winding / analytic orientation; not flipped towards the ray).
    pub ng: Vec3,
    /// Shading frame (`frame.n` is the interpolated shading normal).
    pub frame: Frame,
    /// Texture coordinates.
    pub uv: Vec2,
    /// ∂p/∂u (world space, not normalised).
    pub dpdu: Vec3,
    /// ∂p/∂v (world space, not normalised).
    pub dpdv: Vec3,
    /// Unit direction back along the incoming ray (world space), Mitsuba's `-ray.d`.
    pub wo: Vec3,
    /// Index of the hit shape.
    pub shape: u32,
    /// Primitive (triangle) index within the shape.
    pub prim: u32,
    /// Barycentrics (b1, b2) of the hit in triangle `prim` (zero on analytic shapes).
    pub bary: Vec2,
    /// Index of the shape's material in [`Scene::bsdfs`].
    pub material: u32,
    /// Index of the shape's area light in [`Scene::lights`], if it emits.
    pub light: Option<u32>,
}

impl SurfaceInteraction {
    /// What the BSDF reads at this hit: uv and the differential geometry in the shading frame.
    #[inline]
    pub fn shading_point(&self) -> ShadingPoint {
        ShadingPoint {
            tex: self.tex(),
            dpdu: self.frame.to_local(self.dpdu),
            dpdv: self.frame.to_local(self.dpdv),
            ng: self.frame.to_local(self.ng),
        }
    }

    /// Where textures are looked up at this hit (uv, triangle, barycentrics).
    #[inline]
    pub fn tex(&self) -> TexPoint {
        TexPoint::new(self.uv, self.prim, self.bary)
    }

    /// World vector → shading frame.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        self.frame.to_local(v)
    }

    /// Shading frame → world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.frame.to_world(v)
    }

    /// A ray leaving the surface in world direction `d` (offset against self-intersection).
    #[inline]
    pub fn spawn_ray(&self, d: Vec3) -> Ray {
        spawn_ray(self.p, self.ng, d)
    }

    /// A shadow ray from the surface to point `q`, stopping just short of it.
    #[inline]
    pub fn spawn_ray_to(&self, q: Vec3) -> Ray {
        spawn_ray_to(self.p, self.ng, q)
    }
}

/// Per-shape lookups.
#[derive(Debug, Clone)]
pub struct ShapeInfo {
    /// The shape's name (for messages).
    pub name: String,
    /// Index into [`Scene::bsdfs`].
    pub material: u32,
    /// Index into [`Scene::lights`] of the shape's area light.
    pub light: Option<u32>,
    /// The participating media on either side of the shape's surface.
    pub media: MediumInterface,
}

/// Most emitting surfaces [`Scene::intersect_behind_emitters`] passes through on one ray; a
/// ray still on an emitter after that many is treated as escaped.
const MAX_EMITTER_SKIPS: usize = 256;

/// A scene ready for rendering.
pub struct Scene {
    /// The camera.
    pub camera: Camera,
    /// Shapes (geometry).
    pub shapes: Vec<Shape>,
    /// Material and emitter of each shape.
    pub shape_info: Vec<ShapeInfo>,
    /// Materials.
    pub bsdfs: Vec<Bsdf>,
    /// All lights; area lights refer to their shape.
    pub lights: Vec<Light>,
    /// Light selection for next-event estimation.
    light_selection: LightSelection,
    /// Light selection for photon emission, proportional to power (boxed: the hot fields of
    /// the scene keep their place).
    photon_selection: Box<Distribution1D>,
    /// Indices of environment lights (constant and map).
    environment_lights: Vec<u32>,
    /// Sum of the constant environment lights' radiance.
    environment_radiance: Rgb,
    /// Indices of environment-map lights (their radiance depends on the direction).
    environment_maps: Vec<u32>,
    /// Ray-tracing acceleration structure.
    accel: Bvh4Accel,
    /// The same over emitting shapes only, for rays that only look for emitted light.
    emitter_accel: Bvh4Accel,
    /// Bounding box (min, max) of all shapes.
    bounds: (Vec3, Vec3),
    /// Bounding sphere of all shapes (and the camera), for infinite lights.
    sphere: SceneSphere,
    /// Integrator settings from the file.
    pub integrator: Option<IntegratorDesc>,
    /// Samples per pixel from the file.
    pub sample_count: Option<u32>,
    /// Participating media; shapes and the camera refer to them by index.
    pub media: Vec<Medium>,
    /// The medium the camera sits in.
    pub camera_medium: Option<u32>,
}

fn finite_rgb(c: Rgb) -> bool {
    c.is_finite() && c.min_element() >= 0.0
}

impl Scene {
    /// Builds BVH, lights and lookups from a description; rejects inconsistent data with an
    /// error naming the offending shape or emitter.
    pub fn build(desc: &SceneDescription) -> Result<Scene> {
        Self::build_with(desc, Vec::new())
    }

    /// [`Scene::build`] taking the description's meshes over instead of copying them (a mesh
    /// is otherwise held twice while the scene is built, and as long as the description lives).
    pub fn from_description(mut desc: SceneDescription) -> Result<Scene> {
        let geometries = desc
            .shapes
            .iter_mut()
            .map(|s| std::mem::replace(&mut s.geometry, Geometry::Mesh(Default::default())))
            .collect();
        Self::build_with(&desc, geometries)
    }

    /// [`Scene::build`] with the shapes' geometry taken from `geometries` (one per shape, in
    /// order) when it is not empty, else copied from `desc`.
    fn build_with(desc: &SceneDescription, geometries: Vec<Geometry>) -> Result<Scene> {
        let cam = &desc.camera;
        if cam.width == 0 || cam.height == 0 {
            bail!("film size {}x{} is empty", cam.width, cam.height);
        }
        if !(cam.fov.is_finite() && cam.fov > 0.0 && cam.fov < 180.0) {
            bail!("camera fov {} is outside (0, 180) degrees", cam.fov);
        }
        let mut shapes = Vec::with_capacity(desc.shapes.len());
        let mut shape_info = Vec::with_capacity(desc.shapes.len());
        let mut lights = Vec::new();
        let mut geometries = geometries.into_iter();
        for (i, s) in desc.shapes.iter().enumerate() {
            let owned = geometries.next();
            let geometry = owned.as_ref().unwrap_or(&s.geometry);
            if s.bsdf >= desc.bsdfs.len() {
                bail!(
                    "shape '{}' refers to material {} but only {} exist",
                    s.name,
                    s.bsdf,
                    desc.bsdfs.len()
                );
            }
            match geometry {
                Geometry::Mesh(m) => {
                    let nv = m.positions.len();
                    if let Some(t) = m
                        .indices
                        .iter()
                        .find(|t| t.iter().any(|&v| v as usize >= nv))
                    {
                        bail!(
                            "mesh '{}' has triangle {:?} indexing past its {} vertices",
                            s.name,
                            t,
                            nv
                        );
                    }
                    if m.positions.iter().any(|p| !p.is_finite()) {
                        bail!("mesh '{}' has non-finite vertex positions", s.name);
                    }
                    if m.normals.as_ref().is_some_and(|n| n.len() != nv)
                        || m.uvs.as_ref().is_some_and(|u| u.len() != nv)
                    {
                        bail!(
                            "mesh '{}' has per-vertex normals/uvs not matching its {} vertices",
                            s.name,
                            nv
                        );
                    }
                }
                Geometry::Sphere { center, radius, .. } => {
                    if !(center.is_finite() && radius.is_finite() && *radius > 0.0) {
                        bail!(
                            "sphere '{}' has invalid centre {:?} or radius {}",
                            s.name,
                            center,
                            radius
                        );
                    }
                }
                Geometry::Disk { to_world, .. } => {
                    if !to_world.is_finite() || to_world.determinant() == 0.0 {
                        bail!("disk '{}' has a singular or non-finite to_world", s.name);
                    }
                }
                Geometry::Cylinder {
                    to_world,
                    flip_normals,
                } => {
                    if let Err(e) = crate::shapes::Cylinder::new(*to_world, *flip_normals) {
                        bail!("cylinder '{}': {e}", s.name);
                    }
                }
            }
            let shape = match owned {
                Some(g) => Shape::from_geometry(g),
                None => Shape::new(&s.geometry),
            };
            let light = match &s.emission {
                Some(l) if !l.is_finite_non_negative() => match l {
                    Texture::Constant(c) => bail!(
                        "area emitter of shape '{}' has invalid radiance {c:?}",
                        s.name
                    ),
                    _ => bail!(
                        "area emitter of shape '{}': its radiance texture has negative or non-finite values",
                        s.name
                    ),
                },
                Some(l) if l.mean().max_element() > 0.0 && shape.area() > 0.0 => {
                    let light = AreaLight::new(i as u32, &shape, l.clone(), s.collimated);
                    lights.push(Light::Area(light));
                    Some(lights.len() as u32 - 1)
                }
                _ => None,
            };
            for m in [s.media.interior, s.media.exterior].into_iter().flatten() {
                if m as usize >= desc.media.len() {
                    bail!(
                        "shape '{}' refers to medium #{m}, which does not exist",
                        s.name
                    );
                }
            }
            shape_info.push(ShapeInfo {
                name: s.name.clone(),
                material: s.bsdf as u32,
                light,
                media: s.media,
            });
            shapes.push(shape);
        }
        let mut environment_lights = Vec::new();
        let mut environment_radiance = Rgb::ZERO;
        let mut environment_maps = Vec::new();
        for (i, e) in desc.emitters.iter().enumerate() {
            let light = match e.clone() {
                EmitterDesc::Point {
                    position,
                    intensity,
                } => {
                    if !finite_rgb(intensity) || !position.is_finite() {
                        bail!("point emitter #{i} has invalid intensity or position");
                    }
                    Light::Point(PointLight {
                        position,
                        intensity,
                    })
                }
                EmitterDesc::Spot {
                    to_world,
                    intensity,
                    cutoff_angle,
                    beam_width,
                    texture,
                } => {
                    let cutoff_ok = cutoff_angle > 0.0 && cutoff_angle <= 180.0;
                    if !finite_rgb(intensity)
                        || !cutoff_ok
                        || beam_width.is_nan()
                        || beam_width < 0.0
                    {
                        bail!("spot emitter #{i}: invalid intensity, cutoff_angle {cutoff_angle} or beam_width {beam_width}");
                    }
                    if texture
                        .as_ref()
                        .is_some_and(|t| !t.is_finite_non_negative())
                    {
                        bail!("spot emitter #{i}: its texture has a negative or non-finite value");
                    }
                    Light::Spot(SpotLight::new(
                        to_world,
                        intensity,
                        cutoff_angle,
                        beam_width,
                        texture.clone(),
                    ))
                }
                EmitterDesc::Projector {
                    to_world,
                    irradiance,
                    scale,
                    fov_x,
                } => {
                    let valid = irradiance.is_finite_non_negative()
                        && scale.is_finite()
                        && scale >= 0.0
                        && fov_x > 0.0
                        && fov_x < 180.0;
                    if !valid {
                        bail!("projector emitter #{i}: invalid irradiance, scale {scale} or fov {fov_x}");
                    }
                    Light::Projector(ProjectorLight::new(
                        to_world,
                        irradiance.clone(),
                        scale,
                        fov_x,
                    ))
                }
                EmitterDesc::Directional {
                    direction,
                    irradiance,
                } => {
                    if !finite_rgb(irradiance)
                        || !direction.is_finite()
                        || direction.length_squared() == 0.0
                    {
                        bail!("directional emitter #{i} has invalid irradiance or direction");
                    }
                    Light::Directional(DirectionalLight {
                        direction: direction.normalize(),
                        irradiance,
                    })
                }
                EmitterDesc::Constant { radiance } => {
                    if !finite_rgb(radiance) {
                        bail!("constant emitter #{i} has invalid radiance {radiance:?}");
                    }
                    environment_lights.push(lights.len() as u32);
                    environment_radiance += radiance;
                    Light::Constant(ConstantLight { radiance })
                }
                EmitterDesc::Envmap {
                    image,
                    to_world,
                    scale,
                    filename,
                } => {
                    let map = EnvmapLight::new(&image, to_world, scale).map_err(|e| {
                        anyhow::anyhow!("envmap emitter #{i} ({}): {e}", filename.display())
                    })?;
                    environment_lights.push(lights.len() as u32);
                    environment_maps.push(lights.len() as u32);
                    Light::Envmap(Box::new(map))
                }
            };
            lights.push(light);
        }

        let accel = Bvh4Accel::build(&shapes)?;
        let emitter_accel = Bvh4Accel::build_subset(&shapes, |i| shape_info[i].light.is_some())?;
        let (mut lo, mut hi) = shapes.iter().map(Shape::bounds).fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), (a, b)| (lo.min(a), hi.max(b)),
        );
        if shapes.is_empty() {
            lo = Vec3::ZERO;
            hi = Vec3::ZERO;
        }
        // Radii, the bounding sphere and photon emission all derive from the extent: a vertex
        // near f32::MAX would turn them into infinities, and every SPPM radius with them.
        if !(hi - lo).length().is_finite() {
            bail!(
                "the geometry's bounding box ({lo} to {hi}) is too large for single precision: \
                 its diagonal overflows (a vertex coordinate near ±3.4e38?)"
            );
        }
        let camera = Camera::new(cam);
        // Infinite lights must cover the camera too (a camera outside the geometry sees them).
        let (slo, shi) = (lo.min(camera.position()), hi.max(camera.position()));
        let center = 0.5 * (slo + shi);
        let radius = (0.5 * (shi - slo).length()).max(1e-3) * 1.01;
        let sphere = SceneSphere { center, radius };

        let powers: Vec<f32> = lights
            .iter()
            .map(|l| channel_mean(light_power(l, &shapes, &sphere)))
            .collect();
        let bounds: Vec<EmitterBounds> = lights.iter().map(|l| light_bounds(l, &shapes)).collect();
        // A collimated light sends nothing NEE could sample: no share of the light samples.
        let nee_powers: Vec<f32> = lights
            .iter()
            .zip(&powers)
            .map(|(l, &p)| if l.is_collimated() { 0.0 } else { p })
            .collect();
        for m in &desc.media {
            if let Err(e) = m.validate() {
                bail!("medium '{}': {e}", m.name);
            }
        }
        if desc
            .camera_medium
            .is_some_and(|m| m as usize >= desc.media.len())
        {
            bail!("the camera refers to a medium that does not exist");
        }
        Ok(Scene {
            camera,
            shapes,
            shape_info,
            bsdfs: desc.bsdfs.clone(),
            light_selection: LightSelection::new(&nee_powers, &bounds),
            photon_selection: Box::new(Distribution1D::new(&powers)),
            lights,
            environment_lights,
            environment_radiance,
            environment_maps,
            accel,
            emitter_accel,
            bounds: (lo, hi),
            sphere,
            integrator: desc.integrator.clone(),
            sample_count: desc.sample_count,
            media: desc.media.clone(),
            camera_medium: desc.camera_medium,
        })
    }

    /// Whether the scene has participating media (only `volpath` renders them).
    pub fn has_media(&self) -> bool {
        !self.media.is_empty()
    }

    /// How far from `p` infinite lights (directional, constant, environment map) sit for a
    /// medium that no surface bounds: Mitsuba's 2·max(R, |p − c|) for the bounding sphere
    /// (c, R) of the shapes' bounding box. Without it, a sun or sky behind a haze that fills
    /// the scene would be extinguished by infinitely much medium; with it a sun through fog
    /// renders as in Mitsuba's `volpath`.
    pub fn infinite_light_distance(&self, p: Vec3) -> f32 {
        let (lo, hi) = self.bounds;
        let center = 0.5 * (lo + hi);
        let radius = (0.5 * (hi - lo).length()) * (1.0 + 1e-4);
        2.0 * radius.max((p - center).length())
    }

    /// The error for integrator `name`, which cannot render participating media, when the
    /// scene has some.
    pub fn refuse_media(&self, name: &str) -> Result<()> {
        match self.media.first() {
            Some(m) => bail!(
                "the scene has participating media (medium '{}'{}); the {name} integrator \
                 does not render them (`render --integrator volpath` does)",
                m.name,
                match self.media.len() {
                    1 => String::new(),
                    n => format!(" and {} more", n - 1),
                }
            ),
            None => Ok(()),
        }
    }

    /// Bounding box (min, max) of the geometry.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    /// Length of the geometry's bounding-box diagonal.
    pub fn diagonal(&self) -> f32 {
        (self.bounds.1 - self.bounds.0).length()
    }

    /// Whether the scene file's integrator hides emitters seen directly from the camera
    /// (Mitsuba's `hide_emitters`).
    pub fn hide_emitters(&self) -> bool {
        self.integrator.as_ref().is_some_and(|i| i.hide_emitters)
    }

    /// Bounding sphere used by infinite lights.
    pub fn bounding_sphere(&self) -> SceneSphere {
        self.sphere
    }

    /// Whether the scene has an environment light (rays that escape see radiance).
    pub fn has_environment(&self) -> bool {
        !self.environment_lights.is_empty()
    }

    /// The material at a hit.
    #[inline]
    pub fn bsdf(&self, si: &SurfaceInteraction) -> &Bsdf {
        &self.bsdfs[si.material as usize]
    }

    /// The closest surface hit by `ray`. Always inlined: the photon and eye loops lose ≈ 6 %
    /// when the compiler keeps it out of line (measured when the BSDF enum grew).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        let hit = self.accel.intersect(ray)?;
        Some(self.interaction(ray, &hit))
    }

    /// The closest surface hit by a camera ray that sees through area emitters, as Mitsuba 3's
    /// `hide_emitters` does: a hit on an emitting shape continues the ray in the same direction
    /// from that surface, so the camera shows what lies behind the light (the light's own
    /// surface, lit or not, is not seen). `None` when the ray escapes. The hit's `t` is its
    /// distance from `ray`'s origin, also behind skipped emitters.
    pub fn intersect_behind_emitters(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        let origin = ray.o;
        let mut ray = *ray;
        // Each step starts past the previous surface (`spawn_ray`'s offset), so the loop ends;
        // the bound only guards against a stack of coincident emitters the offset cannot clear.
        for skipped in 0..MAX_EMITTER_SKIPS {
            let mut si = self.intersect(&ray)?;
            if si.light.is_none() {
                if skipped > 0 {
                    si.t = (si.p - origin).length();
                }
                return Some(si);
            }
            ray = Ray {
                tmax: ray.tmax - si.t,
                ..si.spawn_ray(ray.d)
            };
        }
        None
    }

    /// What a ray that only looks for emitted light finds — the BSDF-sampling half of a
    /// light-sampling MIS pair at a vertex where the path ends. The answer is the one
    /// [`Self::intersect`] implies, but cheaper: the closest hit is searched among emitting
    /// shapes only (usually a handful of primitives), and the rest of the scene is asked only
    /// whether it blocks the ray before that hit (or, with an environment light, at all).
    #[inline]
    pub fn intersect_emitter(&self, ray: &Ray) -> EmitterHit {
        if let Some(hit) = self.emitter_accel.intersect(ray) {
            // Strictly before the emitter: the occlusion test computes the emitter's own
            // distance exactly as the emitter BVH did, so the emitter does not block itself.
            let before = Ray {
                tmax: hit.t,
                ..*ray
            };
            if self.accel.occluded(&before) {
                EmitterHit::Blocked
            } else {
                EmitterHit::Emitter(self.interaction(ray, &hit))
            }
        } else if self.has_environment() && !self.accel.occluded(ray) {
            EmitterHit::Escaped
        } else {
            EmitterHit::Blocked
        }
    }

    /// The surface interaction of an accelerator hit along `ray`.
    #[inline(always)]
    fn interaction(&self, ray: &Ray, hit: &PrimitiveHit) -> SurfaceInteraction {
        let shape = &self.shapes[hit.shape as usize];
        let g = shape.hit_geometry(hit.prim, ray, hit.t, hit.bary);
        let info = &self.shape_info[hit.shape as usize];
        SurfaceInteraction {
            p: g.p,
            t: hit.t,
            ng: g.ng,
            frame: Frame::from_normal_tangent(g.ns, g.dpdu),
            uv: g.uv,
            dpdu: g.dpdu,
            dpdv: g.dpdv,
            wo: -ray.d,
            shape: hit.shape,
            prim: hit.prim,
            bary: g.bary,
            material: info.material,
            light: info.light,
        }
    }

    /// Whether anything blocks `ray` within its `[tmin, tmax]`.
    #[inline]
    pub fn occluded_ray(&self, ray: &Ray) -> bool {
        self.accel.occluded(ray)
    }

    /// Whether the segment from surface point `p` (geometric normal `ng`) to point `q` is blocked.
    #[inline]
    pub fn occluded(&self, p: Vec3, ng: Vec3, q: Vec3) -> bool {
        self.accel.occluded(&spawn_ray_to(p, ng, q))
    }

    /// Whether the light sample `ls`, taken from surface point `p` (geometric normal `ng`), is
    /// blocked; infinite lights test an unbounded ray.
    // `always`: the per-vertex NEE calls sit in the integrators' hot loops, and with
    // `#[inline]` alone rustc's choice flips with unrelated edits (once: 4 % of a path-traced
    // sample spent in the calls).
    #[inline(always)]
    pub fn light_occluded(&self, p: Vec3, ng: Vec3, ls: &LightSample) -> bool {
        if ls.infinite {
            self.accel
                .occluded(&Ray::new(offset_point(p, ng, ls.wi), ls.wi))
        } else {
            self.accel.occluded(&spawn_ray_to(p, ng, ls.p))
        }
    }

    /// Radiance emitted by the surface at `si` towards world direction `w` (zero unless it is an
    /// area light seen from its front side, judged by the shading normal as Mitsuba does).
    #[inline]
    pub fn emitted(&self, si: &SurfaceInteraction, w: Vec3) -> Rgb {
        match si.light {
            Some(l) => match &self.lights[l as usize] {
                Light::Area(a) => a.eval(si.frame.n, w, si.tex()),
                _ => Rgb::ZERO,
            },
            None => Rgb::ZERO,
        }
    }

    /// Radiance arriving along a ray that escapes the scene in direction `d`.
    #[inline]
    pub fn environment(&self, d: Vec3) -> Rgb {
        let mut radiance = self.environment_radiance;
        for &i in &self.environment_maps {
            if let Light::Envmap(map) = &self.lights[i as usize] {
                radiance += map.eval(d);
            }
        }
        radiance
    }

    /// Probability of selecting light `i` for next-event estimation ([`Self::sample_li`]) at
    /// point `p` with geometric normal `n` (`Vec3::ZERO`: none; the point matters for finite
    /// lights only, see [`LightSelection`]).
    #[inline]
    pub fn light_pmf(&self, p: Vec3, n: Vec3, i: u32) -> f32 {
        self.light_selection.pmf(p, n, i)
    }

    /// Probability of selecting light `i` to emit a photon ([`Self::sample_emission`]): its
    /// share of the total power.
    #[inline]
    pub fn photon_light_pmf(&self, i: u32) -> f32 {
        self.photon_selection().pmf(i as usize)
    }

    /// The photons' light selection (by power).
    #[inline]
    fn photon_selection(&self) -> &Distribution1D {
        &self.photon_selection
    }

    /// Emitted power of light `i`.
    pub fn light_power(&self, i: u32) -> Rgb {
        light_power(&self.lights[i as usize], &self.shapes, &self.sphere)
    }

    /// Samples a light ([`LightSelection`]) and a direction towards it from point `p` with
    /// geometric normal `n` (`Vec3::ZERO`: none). `u_sel` picks the light (and, rescaled, the
    /// triangle of a mesh light), `u` the point/direction. The returned `pdf` and `weight`
    /// include the selection probability.
    #[inline(always)]
    pub fn sample_li(&self, p: Vec3, n: Vec3, u_sel: f32, u: Vec2) -> Option<LightSample> {
        if self.lights.is_empty() {
            return None;
        }
        let (i, pmf, u_rest) = self.light_selection.sample(p, n, u_sel);
        if pmf == 0.0 {
            return None;
        }
        let mut ls = match &self.lights[i] {
            Light::Area(a) => a.sample_li(&self.shapes[a.shape as usize], p, n, u_rest, u)?,
            Light::Point(l) => l.sample_li(p)?,
            Light::Spot(l) => l.sample_li(p)?,
            Light::Projector(l) => l.sample_li(p)?,
            Light::Directional(l) => l.sample_li(p, &self.sphere),
            Light::Constant(l) => l.sample_li(p, u, &self.sphere),
            Light::Envmap(l) => l.sample_li(p, u, &self.sphere)?,
        };
        ls.light = i as u32;
        ls.pdf *= pmf;
        ls.weight /= pmf;
        Some(ls)
    }

    /// Solid-angle density (selection included) with which [`Self::sample_li`] from `p_ref`
    /// with geometric normal `n_ref` would produce the direction that hit the area light at
    /// `si`.
    #[inline]
    pub fn pdf_li_surface(&self, p_ref: Vec3, n_ref: Vec3, si: &SurfaceInteraction) -> f32 {
        match si.light {
            Some(l) => match &self.lights[l as usize] {
                Light::Area(a) => {
                    let shape = &self.shapes[a.shape as usize];
                    a.pdf_li(shape, p_ref, n_ref, si.p, si.frame.n, si.prim)
                        * self.light_pmf(p_ref, n_ref, l)
                }
                _ => 0.0,
            },
            None => 0.0,
        }
    }

    /// Solid-angle density (selection included) of sampling escaping direction `d` through the
    /// environment lights from `p_ref` with geometric normal `n_ref` (the selection may depend
    /// on the normal when a directional light shares the infinite lights' share).
    #[inline]
    pub fn pdf_li_environment(&self, p_ref: Vec3, n_ref: Vec3, d: Vec3) -> f32 {
        self.environment_lights
            .iter()
            .map(|&i| match &self.lights[i as usize] {
                Light::Constant(c) => c.pdf_li() * self.light_pmf(p_ref, n_ref, i),
                Light::Envmap(m) => m.pdf_li(d) * self.light_pmf(p_ref, n_ref, i),
                _ => 0.0,
            })
            .sum()
    }

    /// Samples a photon: a light by power, then a ray leaving it. `flux` includes the selection
    /// probability, so the average of `flux` over photons estimates the total emitted power.
    /// With a `focus`, an infinite light's photon starts from [`PhotonFocus`]'s mixture (same
    /// expectation) instead of uniformly on the scene's bounding disk.
    pub fn sample_emission(
        &self,
        u_sel: f32,
        u_pos: Vec2,
        u_dir: Vec2,
        focus: Option<&PhotonFocus>,
    ) -> Option<EmissionSample> {
        if self.lights.is_empty() {
            return None;
        }
        let (i, pmf, u_rest) = self.photon_selection().sample(u_sel);
        if pmf == 0.0 {
            return None;
        }
        let mut e = match &self.lights[i] {
            Light::Area(a) => {
                a.sample_emission(&self.shapes[a.shape as usize], u_rest, u_pos, u_dir)
            }
            Light::Point(l) => l.sample_emission(u_dir),
            Light::Spot(l) => l.sample_emission(u_dir),
            Light::Projector(l) => l.sample_emission(u_dir),
            Light::Directional(l) => l.sample_emission(u_pos, &self.sphere),
            Light::Constant(l) => l.sample_emission(u_dir, u_pos, &self.sphere),
            Light::Envmap(l) => l.sample_emission(u_dir, u_pos, &self.sphere),
        };
        e.light = i as u32;
        e.flux /= pmf;
        if let Some(focus) = focus.filter(|_| self.lights[i].is_infinite()) {
            // The light drew the direction (and the flux it carries) from `u_dir`; the start
            // on the disk facing it is re-drawn from the mixture with the same `u_pos`.
            let (origin, factor) = focus.origin(&self.sphere, e.ray.d, u_pos);
            e.ray = Ray::new(origin, e.ray.d);
            e.flux *= factor;
        }
        (e.flux.max_element() > 0.0).then_some(e)
    }
}

/// The emission bounds of a light, for the light selection.
fn light_bounds(l: &Light, shapes: &[Shape]) -> EmitterBounds {
    match l {
        Light::Area(a) => EmitterBounds::Finite(a.bounds(&shapes[a.shape as usize])),
        Light::Point(p) => EmitterBounds::Finite(p.bounds()),
        Light::Spot(s) => EmitterBounds::Finite(s.bounds()),
        Light::Projector(p) => EmitterBounds::Finite(p.bounds()),
        Light::Directional(d) => d.bounds(),
        Light::Constant(c) => c.bounds(),
        Light::Envmap(m) => m.bounds(),
    }
}

fn light_power(l: &Light, shapes: &[Shape], sphere: &SceneSphere) -> Rgb {
    match l {
        Light::Area(a) => a.power(&shapes[a.shape as usize]),
        Light::Point(p) => p.power(),
        Light::Spot(s) => s.power(),
        Light::Projector(p) => p.power(),
        Light::Directional(d) => d.power(sphere),
        Light::Constant(c) => c.power(sphere),
        Light::Envmap(m) => m.power(sphere),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Diffuse;
    use crate::description::{CameraDesc, FovAxis, ShapeDesc, TriangleMesh};
    use crate::sampling::{
        power_heuristic, rng_for, square_to_uniform_sphere, UniformSource, UNIFORM_SPHERE_PDF,
    };
    use crate::texture::Texture;
    use glam::Mat4;

    fn desc(shapes: Vec<ShapeDesc>, emitters: Vec<EmitterDesc>) -> SceneDescription {
        SceneDescription {
            camera: CameraDesc {
                to_world: Mat4::IDENTITY,
                projection: crate::description::Projection::Perspective,
                fov: 45.0,
                fov_axis: FovAxis::X,
                near_clip: 0.01,
                far_clip: 100.0,
                aperture_radius: 0.0,
                focus_distance: 1.0,
                width: 4,
                height: 4,
                filter: crate::filter::FilterDesc::Box,
                sample_border: false,
                crop: None,
                principal_point: glam::Vec2::ZERO,
            },
            sample_count: None,
            integrator: None,
            bsdfs: vec![Bsdf::Diffuse(Diffuse {
                reflectance: Texture::Constant(Rgb::splat(0.5)),
            })],
            shapes,
            emitters,
            warnings: vec![],
            media: vec![],
            camera_medium: None,
        }
    }

    /// A 2×1 quad at height y = 1 whose front side faces down (−y).
    fn ceiling_light() -> ShapeDesc {
        ShapeDesc {
            name: "light".into(),
            geometry: Geometry::Mesh(TriangleMesh {
                positions: vec![
                    Vec3::new(-1.0, 1.0, -0.5),
                    Vec3::new(1.0, 1.0, -0.5),
                    Vec3::new(1.0, 1.0, 0.5),
                    Vec3::new(-1.0, 1.0, 0.5),
                ],
                normals: None,
                uvs: None,
                indices: vec![[0, 1, 2], [0, 2, 3]],
                flipped: false,
            }),
            bsdf: 0,
            emission: Some(Texture::Constant(Rgb::new(1.0, 2.0, 3.0))),
            collimated: false,
            media: Default::default(),
        }
    }

    fn ball_light(center: Vec3, radius: f32) -> ShapeDesc {
        ShapeDesc {
            name: "ball".into(),
            geometry: Geometry::Sphere {
                center,
                radius,
                rotation: glam::Mat3::IDENTITY,
                flip_normals: false,
            },
            bsdf: 0,
            emission: Some(Texture::Constant(Rgb::ONE)),
            collimated: false,
            media: Default::default(),
        }
    }

    /// ∫ pdf_li dω over the sphere of directions from `p`, by uniform direction sampling.
    fn integrate_pdf(scene: &Scene, p: Vec3, n: usize) -> f64 {
        let mut rng = rng_for(11, 0, 0);
        let mut acc = 0.0f64;
        for _ in 0..n {
            let d = square_to_uniform_sphere(rng.next_2d());
            if let Some(si) = scene.intersect(&Ray::new(p, d)) {
                acc += (scene.pdf_li_surface(p, Vec3::ZERO, &si) / UNIFORM_SPHERE_PDF) as f64;
            }
        }
        acc / n as f64
    }

    /// A non-emitting sphere (occluder) of radius `radius` at `center`.
    fn ball(center: Vec3, radius: f32) -> ShapeDesc {
        ShapeDesc {
            emission: None,
            collimated: false,
            media: Default::default(),
            name: "occluder".into(),
            ..ball_light(center, radius)
        }
    }

    /// A scene built from an owned description (its meshes taken over) is the scene built
    /// from a borrowed one: the same mesh data, lights and hits; and the owned geometry is
    /// what gets checked (a mesh indexing past its vertices is refused by both).
    #[test]
    fn owned_description_builds_the_same_scene() {
        let shapes = vec![
            ceiling_light(),
            ball_light(Vec3::new(1.5, 0.0, 0.0), 0.4),
            ball(Vec3::new(0.0, 0.5, 0.0), 0.3),
        ];
        let d = desc(shapes, vec![]);
        let copied = Scene::build(&d).unwrap();
        let owned = Scene::from_description(d.clone()).unwrap();
        assert_eq!(owned.shapes.len(), copied.shapes.len());
        assert_eq!(owned.lights.len(), copied.lights.len());
        let (Shape::Mesh(a), Shape::Mesh(b)) = (&owned.shapes[0], &copied.shapes[0]) else {
            panic!("shape 0 is the ceiling mesh");
        };
        assert_eq!(a.data.positions, b.data.positions);
        assert_eq!(a.data.indices, b.data.indices);
        let mut rng = rng_for(5, 0, 0);
        for _ in 0..200 {
            let ray = Ray::new(Vec3::ZERO, square_to_uniform_sphere(rng.next_2d()));
            let (x, y) = (owned.intersect(&ray), copied.intersect(&ray));
            assert_eq!(x.map(|s| (s.p, s.shape)), y.map(|s| (s.p, s.shape)));
        }
        let mut bad = ceiling_light();
        if let Geometry::Mesh(m) = &mut bad.geometry {
            m.indices.push([0, 1, 4]);
        }
        let d = desc(vec![bad], vec![]);
        assert!(Scene::build(&d).is_err());
        let Err(err) = Scene::from_description(d) else {
            panic!("the bad index was not found");
        };
        let err = err.to_string();
        assert!(err.contains("indexing past its 4 vertices"), "{err}");
    }

    #[test]
    fn emitter_probe_answers_as_the_closest_hit_does() {
        for environment in [false, true] {
            let emitters = if environment {
                vec![EmitterDesc::Constant {
                    radiance: Rgb::splat(0.5),
                }]
            } else {
                vec![]
            };
            let scene = Scene::build(&desc(
                vec![
                    ceiling_light(),
                    ball_light(Vec3::new(1.5, 0.0, 0.0), 0.4),
                    ball(Vec3::new(0.0, 0.5, 0.0), 0.3),
                    ball(Vec3::new(-1.0, -0.5, 0.5), 0.6),
                ],
                emitters,
            ))
            .unwrap();
            let mut rng = rng_for(3, 0, 0);
            let mut seen = [0u32; 3];
            for _ in 0..20_000 {
                let o = Vec3::new(
                    4.0 * rng.next_f32() - 2.0,
                    2.0 * rng.next_f32() - 1.0,
                    2.0 * rng.next_f32() - 1.0,
                );
                let ray = Ray::new(o, square_to_uniform_sphere(rng.next_2d()));
                match (scene.intersect_emitter(&ray), scene.intersect(&ray)) {
                    (EmitterHit::Emitter(e), Some(h)) => {
                        assert!(h.light.is_some(), "{ray:?}: emitter behind {h:?}");
                        assert_eq!((e.shape, e.prim, e.t, e.p), (h.shape, h.prim, h.t, h.p));
                        assert_eq!(scene.emitted(&e, e.wo), scene.emitted(&h, h.wo));
                        seen[0] += 1;
                    }
                    (EmitterHit::Escaped, None) => {
                        assert!(environment);
                        seen[1] += 1;
                    }
                    (EmitterHit::Blocked, Some(h)) => {
                        assert!(h.light.is_none(), "{ray:?}: missed emitter {h:?}");
                        seen[2] += 1;
                    }
                    (EmitterHit::Blocked, None) => assert!(!environment),
                    (probe, hit) => panic!("{ray:?}: probe {probe:?} but closest hit {hit:?}"),
                }
            }
            // Every outcome occurs (escapes only with the environment).
            assert!(seen[0] > 1000 && seen[2] > 1000, "{seen:?}");
            assert_eq!(seen[1] > 1000, environment, "{seen:?}");
        }
    }

    /// A light sample's density equals the density of the surface its ray hits, and its MIS
    /// weight against a BSDF density is the power heuristic, summing to one with its complement.
    #[test]
    fn sampled_light_pdf_matches_the_pdf_of_the_hit_and_mis_sums_to_one() {
        let scene = Scene::build(&desc(
            vec![ceiling_light(), ball_light(Vec3::new(3.0, 0.5, 0.0), 0.5)],
            vec![],
        ))
        .unwrap();
        assert_eq!(scene.lights.len(), 2);
        let p = Vec3::new(0.2, 0.0, 0.1);
        // Two finite lights: the selection depends on the point and its normal.
        assert!(scene.light_selection.is_spatial());
        let n = Vec3::new(0.3, 1.0, 0.0).normalize();
        let mut rng = rng_for(5, 0, 0);
        let mut checked = 0;
        for _ in 0..2000 {
            let Some(ls) = scene.sample_li(p, n, rng.next_f32(), rng.next_2d()) else {
                continue;
            };
            let si = scene
                .intersect(&Ray::new(p, ls.wi))
                .expect("the sampled light is visible");
            assert_eq!(si.light, Some(ls.light));
            assert!((si.t - ls.dist).abs() < 1e-3 * ls.dist);
            let pdf = scene.pdf_li_surface(p, n, &si);
            // Near a silhouette the cosine at the light loses relative precision.
            let cos_l = si.frame.n.dot(-ls.wi);
            let tol = if cos_l > 0.05 { 1e-3 } else { 0.05 };
            assert!(
                (pdf - ls.pdf).abs() <= tol * ls.pdf,
                "{pdf} vs {} (cos {cos_l})",
                ls.pdf
            );
            // MIS against any BSDF density for the same direction is the power heuristic
            // l²/(l² + b²), and the two weights sum to one.
            let bsdf_pdf = 0.37 * ls.wi.y.abs();
            let (l, b) = (f64::from(ls.pdf), f64::from(bsdf_pdf));
            let want = l * l / (l * l + b * b);
            let w = f64::from(power_heuristic(ls.pdf, bsdf_pdf));
            assert!(
                (w - want).abs() <= 1e-5,
                "light weight {w} for pdfs {l} (light), {b} (BSDF); want {want}"
            );
            let s = power_heuristic(ls.pdf, bsdf_pdf) + power_heuristic(bsdf_pdf, ls.pdf);
            assert!((s - 1.0).abs() < 1e-5, "MIS weights sum to {s}");
            checked += 1;
        }
        assert!(checked > 1000);
    }

    /// A closed emitting mesh (a torus of 384 triangles) chooses its triangles by what they
    /// deliver to the point ([`crate::lights::emitter_tree`]): each sample's density is
    /// the density `pdf_li_surface` gives its hit; the irradiance NEE estimates equals the one
    /// estimated by area sampling (the selection's expectation is unchanged) at several points
    /// and normals, with less variance.
    #[test]
    fn mesh_light_triangle_choice_keeps_nee_unbiased() {
        let torus = ShapeDesc {
            name: "torus".into(),
            geometry: Geometry::Mesh(crate::lights::emitter_tree::torus(24, 8, 1.0, 0.3)),
            bsdf: 0,
            emission: Some(Texture::Constant(Rgb::new(1.0, 2.0, 3.0))),
            collimated: false,
            media: Default::default(),
        };
        let d = desc(vec![torus], vec![]);
        let scene = Scene::build(&d).unwrap();
        let mut by_area = Scene::build(&d).unwrap();
        let Light::Area(light) = &mut by_area.lights[0] else {
            panic!("the torus is an area light");
        };
        assert!(light.triangles.is_some());
        light.triangles = None;
        let points = [
            (Vec3::new(0.0, 1.5, 0.0), Vec3::Y),
            (
                Vec3::new(2.0, 0.2, 0.5),
                Vec3::new(-1.0, 0.3, 0.0).normalize(),
            ),
            (Vec3::new(0.1, -0.1, 0.2), Vec3::ZERO),
            (Vec3::new(1.6, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0)),
        ];
        for (p, n) in points {
            let mut rng = rng_for(21, 0, 0);
            let mut checked = 0;
            let mut estimate = |scene: &Scene, draws: usize| {
                let (mut sum, mut sum2) = (0.0f64, 0.0f64);
                for _ in 0..draws {
                    let Some(ls) = scene.sample_li(p, n, rng.next_f32(), rng.next_2d()) else {
                        continue;
                    };
                    if checked < 2000 {
                        if let Some(si) = scene.intersect(&Ray::new(p, ls.wi)) {
                            // The sampled point itself, not a part of the torus in front of it.
                            if (si.t - ls.dist).abs() < 1e-4 * ls.dist {
                                let pdf = scene.pdf_li_surface(p, n, &si);
                                assert!(
                                    (pdf - ls.pdf).abs() <= 2e-3 * ls.pdf,
                                    "at {p}: {pdf} vs {}",
                                    ls.pdf
                                );
                                checked += 1;
                            }
                        }
                    }
                    let cos = if n == Vec3::ZERO {
                        1.0
                    } else {
                        n.dot(ls.wi).abs()
                    };
                    let x = (ls.weight.y * cos) as f64;
                    sum += x;
                    sum2 += x * x;
                }
                let mean = sum / draws as f64;
                (mean, (sum2 / draws as f64 - mean * mean) / draws as f64)
            };
            let draws = 400_000;
            let (tree, tree_var) = estimate(&scene, draws);
            let (area, area_var) = estimate(&by_area, draws);
            let sigma = (tree_var + area_var).sqrt();
            assert!(
                (tree - area).abs() < 5.0 * sigma,
                "at {p}: {tree} (tree) vs {area} (area), σ {sigma}"
            );
            // The samples go where the light comes from.
            assert!(
                tree_var < area_var,
                "at {p}: variance {tree_var} vs {area_var}"
            );
        }
    }

    #[test]
    fn area_light_pdfs_integrate_correctly() {
        // A fully visible quad: the density integrates to 1.
        let scene = Scene::build(&desc(vec![ceiling_light()], vec![])).unwrap();
        let i = integrate_pdf(&scene, Vec3::new(0.1, 0.0, 0.0), 400_000);
        assert!((i - 1.0).abs() < 0.02, "{i}");
        // A sphere seen from outside: E[1/pdf] over the successful samples is the solid angle
        // it subtends, 2π(1 − √(1 − r²/d²)).
        let (r, d) = (0.5f32, 2.0f32);
        let scene =
            Scene::build(&desc(vec![ball_light(Vec3::new(0.0, 0.0, d), r)], vec![])).unwrap();
        let mut rng = rng_for(12, 0, 0);
        let n = 400_000;
        let mut acc = 0.0f64;
        for _ in 0..n {
            if let Some(ls) = scene.sample_li(Vec3::ZERO, Vec3::ZERO, rng.next_f32(), rng.next_2d())
            {
                acc += 1.0 / ls.pdf as f64;
            }
        }
        let omega = acc / n as f64;
        let expected = 2.0 * std::f64::consts::PI * (1.0 - (1.0 - (r * r / (d * d)) as f64).sqrt());
        assert!(
            (omega - expected).abs() < 0.01 * expected,
            "{omega} vs {expected}"
        );
    }

    #[test]
    fn photon_flux_averages_to_the_emitted_power() {
        let emitters = vec![
            EmitterDesc::Point {
                position: Vec3::new(0.0, 0.5, 0.0),
                intensity: Rgb::splat(2.0),
            },
            EmitterDesc::Spot {
                to_world: Mat4::from_translation(Vec3::new(0.0, 0.5, 0.0)),
                intensity: Rgb::splat(5.0),
                cutoff_angle: 30.0,
                beam_width: 20.0,
                texture: None,
            },
            // A projected texture: its power is integrated over the cone at build time.
            EmitterDesc::Spot {
                to_world: Mat4::from_translation(Vec3::new(0.3, 0.5, 0.0))
                    * Mat4::from_rotation_x(1.0),
                intensity: Rgb::splat(3.0),
                cutoff_angle: 40.0,
                beam_width: 25.0,
                texture: Some(Texture::Checkerboard {
                    color0: Rgb::new(0.9, 0.1, 0.0),
                    color1: Rgb::new(0.2, 0.3, 0.6),
                    to_uv: glam::Mat3::from_scale(glam::Vec2::new(3.0, 1.7)),
                }),
            },
        ];
        let scene = Scene::build(&desc(vec![ceiling_light()], emitters)).unwrap();
        let total: Rgb = (0..scene.lights.len() as u32)
            .map(|i| scene.light_power(i))
            .sum();
        let mut rng = rng_for(9, 0, 0);
        let n = 200_000;
        let mut acc = glam::DVec3::ZERO;
        for _ in 0..n {
            // A photon may carry nothing (e.g. exactly on a spot's cutoff): it counts as zero.
            let Some(e) = scene.sample_emission(rng.next_f32(), rng.next_2d(), rng.next_2d(), None)
            else {
                continue;
            };
            if e.light == 0 {
                // Area-light photons leave the front (−y) side.
                assert!(e.ray.d.y < 0.0);
            }
            acc += e.flux.as_dvec3();
        }
        let mean = (acc / n as f64).as_vec3();
        assert!(
            ((mean - total) / total).abs().max_element() < 0.01,
            "{mean:?} vs {total:?}"
        );
    }

    #[test]
    fn nee_caps_the_share_of_infinite_lights_and_photons_go_by_power() {
        // Lights: 0 the ceiling (area), 1 a spot, 2 a sky of radiance `sky`.
        let spot = EmitterDesc::Spot {
            to_world: Mat4::from_translation(Vec3::new(0.0, 0.5, 0.0)),
            intensity: Rgb::splat(5.0),
            cutoff_angle: 30.0,
            beam_width: 20.0,
            texture: None,
        };
        let with_sky = |sky: f32| {
            let sky = EmitterDesc::Constant {
                radiance: Rgb::splat(sky),
            };
            Scene::build(&desc(vec![ceiling_light()], vec![spot.clone(), sky])).unwrap()
        };
        for (sky, capped) in [(50.0, true), (0.01, false)] {
            let scene = with_sky(sky);
            let power = |i: u32| channel_mean(scene.light_power(i));
            let total: f32 = (0..3).map(power).sum();
            let finite = power(0) + power(1);
            // Photons: by power, always.
            for i in 0..3 {
                assert!((scene.photon_light_pmf(i) - power(i) / total).abs() < 1e-6);
            }
            // NEE: a sky with more than half the power is capped at 1/2, the finite lights
            // sharing the other half by power; a weaker sky changes nothing.
            assert_eq!(power(2) > finite, capped, "sky {sky}");
            for i in 0..3 {
                let want = match (capped, i) {
                    (true, 2) => 0.5,
                    (true, _) => 0.5 * power(i) / finite,
                    (false, _) => scene.photon_light_pmf(i),
                };
                assert!(
                    (scene.light_selection.by_power().pmf(i as usize) - want).abs() < 1e-6,
                    "sky {sky}, light {i}"
                );
            }
            // With two finite lights the selection depends on the point, but the infinite
            // light keeps its share everywhere and the finite lights share the rest.
            assert!(scene.light_selection.is_spatial());
            for p in [
                Vec3::ZERO,
                Vec3::new(0.5, 0.9, 0.2),
                Vec3::new(-3.0, -2.0, 1.0),
            ] {
                let n = Vec3::Y;
                let sky_pmf = scene.light_pmf(p, n, 2);
                let want = if capped { 0.5 } else { power(2) / total };
                assert!((sky_pmf - want).abs() < 1e-6, "sky {sky} at {p}: {sky_pmf}");
                let sum: f32 = (0..3).map(|i| scene.light_pmf(p, n, i)).sum();
                assert!((sum - 1.0).abs() < 1e-6, "sky {sky} at {p}: {sum}");
            }
        }
        // Two strong infinite lights share 2/3 by their power.
        let sun = EmitterDesc::Directional {
            direction: Vec3::new(0.0, -1.0, 0.0),
            irradiance: Rgb::splat(100.0),
        };
        let sky = EmitterDesc::Constant {
            radiance: Rgb::splat(50.0),
        };
        let both = Scene::build(&desc(vec![ceiling_light()], vec![spot, sun, sky])).unwrap();
        let sky_and_sun: f32 = (2..4).map(|i| both.light_pmf(Vec3::ZERO, Vec3::Y, i)).sum();
        assert!((sky_and_sun - 2.0 / 3.0).abs() < 1e-6);
        // The base weights split that share by power.
        let ratio = both.light_selection.by_power().pmf(2) / both.light_selection.by_power().pmf(3);
        let power_ratio = channel_mean(both.light_power(2)) / channel_mean(both.light_power(3));
        assert!((ratio / power_ratio - 1.0).abs() < 1e-5);
        // NEE stays unbiased: irradiance at a point facing up under a uniform sky L and a
        // point light of intensity I at height h is π·L + I/h², estimated from light samples
        // (visibility ignored).
        // A non-emitting quad gives the scene its size (the sky's power grows with it).
        let mut quad = ceiling_light();
        quad.emission = None;
        let unbiased = Scene::build(&desc(
            vec![quad],
            vec![
                EmitterDesc::Point {
                    position: Vec3::new(0.0, 2.0, 0.0),
                    intensity: Rgb::splat(8.0),
                },
                EmitterDesc::Constant {
                    radiance: Rgb::splat(0.5),
                },
            ],
        ))
        .unwrap();
        let mut rng = rng_for(5, 0, 0);
        let n = 400_000;
        let mut e = 0.0f64;
        for _ in 0..n {
            if let Some(ls) =
                unbiased.sample_li(Vec3::ZERO, Vec3::ZERO, rng.next_f32(), rng.next_2d())
            {
                e += (ls.weight.x * ls.wi.y.max(0.0)) as f64;
            }
        }
        let want = std::f64::consts::PI * 0.5 + 8.0 / 4.0;
        let got = e / n as f64;
        assert!((got - want).abs() < 0.01 * want, "{got} vs {want}");
    }

    /// With several finite lights, and a sun next to a sky, NEE picks them by their importance
    /// at the point, and the estimate stays unbiased: the irradiance on a surface under two
    /// point lights, a spot (full beam there), a sun and a sky is Σ I·cos θ / d² + E·cos θ +
    /// π·L, whatever the normal (visibility ignored).
    #[test]
    fn spatial_light_selection_keeps_nee_unbiased() {
        let spot = EmitterDesc::Spot {
            to_world: Mat4::from_rotation_translation(
                glam::Quat::from_rotation_arc(
                    Vec3::Z,
                    (Vec3::new(0.4, 0.0, 0.1) - Vec3::new(0.5, 3.0, 0.0)).normalize(),
                ),
                Vec3::new(0.5, 3.0, 0.0),
            ),
            intensity: Rgb::splat(20.0),
            cutoff_angle: 20.0,
            beam_width: 15.0,
            texture: None,
        };
        let point = |x: f32, y: f32, i: f32| EmitterDesc::Point {
            position: Vec3::new(x, y, 0.0),
            intensity: Rgb::splat(i),
        };
        // A non-emitting quad gives the scene its size (the infinite lights' power grows with
        // it).
        let mut quad = ceiling_light();
        quad.emission = None;
        let scene = Scene::build(&desc(
            vec![quad],
            vec![
                point(0.0, 2.0, 8.0),
                point(-6.0, 1.0, 30.0),
                spot,
                EmitterDesc::Directional {
                    direction: Vec3::new(0.6, -0.8, 0.0),
                    irradiance: Rgb::splat(2.0),
                },
                EmitterDesc::Constant {
                    radiance: Rgb::splat(1.0),
                },
            ],
        ))
        .unwrap();
        assert!(scene.light_selection.is_spatial());
        let p = Vec3::new(0.4, 0.0, 0.1);
        for n in [Vec3::Y, Vec3::new(0.6, 0.8, 0.0), Vec3::new(-0.8, 0.6, 0.0)] {
            let mut want = 0.0f64;
            for (q, i) in [
                (Vec3::new(0.0, 2.0, 0.0), 8.0f32),
                (Vec3::new(-6.0, 1.0, 0.0), 30.0),
                (Vec3::new(0.5, 3.0, 0.0), 20.0),
            ] {
                let d = q - p;
                want += (i * n.dot(d.normalize()).max(0.0) / d.length_squared()) as f64;
            }
            // The sun and the sky (π·L on the surface's upper side).
            want += (2.0 * n.dot(Vec3::new(-0.6, 0.8, 0.0)).max(0.0)) as f64;
            want += std::f64::consts::PI;
            let mut rng = rng_for(9, 0, 0);
            let count = 400_000;
            let mut got = 0.0f64;
            for _ in 0..count {
                if let Some(ls) = scene.sample_li(p, n, rng.next_f32(), rng.next_2d()) {
                    got += (ls.weight.x * ls.wi.dot(n).max(0.0)) as f64;
                    if ls.infinite && !ls.delta {
                        // The sky's density as MIS sees it from the same point.
                        let pdf = scene.pdf_li_environment(p, n, ls.wi);
                        assert!((pdf - ls.pdf).abs() <= 1e-5 * ls.pdf, "{pdf} vs {}", ls.pdf);
                    }
                }
            }
            got /= count as f64;
            assert!(
                (got - want).abs() < 0.01 * want,
                "normal {n}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn point_light_follows_the_inverse_square_law() {
        let emitters = vec![EmitterDesc::Point {
            position: Vec3::new(0.0, 2.0, 0.0),
            intensity: Rgb::splat(8.0),
        }];
        let scene = Scene::build(&desc(vec![], emitters)).unwrap();
        let ls = scene
            .sample_li(Vec3::ZERO, Vec3::ZERO, 0.3, glam::Vec2::splat(0.5))
            .unwrap();
        assert!(ls.delta && (ls.wi - Vec3::Y).length() < 1e-6);
        assert!((ls.weight - Rgb::splat(2.0)).abs().max_element() < 1e-5);
    }

    /// An area light with a checkerboard radiance over its uvs (a 2×1 quad facing down at
    /// y = 1, uv spanning the quad): photons carry L(uv)·π/pdf, averaging to its power π·A·L̄;
    /// light samples carry L at the sampled point, so E[weight·cos θ] is the irradiance found by
    /// quadrature over the quad; and the light seen from below shows the checkerboard.
    #[test]
    fn textured_area_light_emits_its_texture() {
        let (c0, c1) = (Rgb::new(2.0, 1.0, 0.5), Rgb::new(0.0, 0.5, 3.0));
        let checker = Texture::Checkerboard {
            color0: c0,
            color1: c1,
            to_uv: glam::Mat3::from_scale(glam::Vec2::new(4.0, 2.0)),
        };
        let mut light = ceiling_light();
        if let Geometry::Mesh(m) = &mut light.geometry {
            m.uvs = Some(vec![
                Vec2::new(0.0, 0.0),
                Vec2::new(1.0, 0.0),
                Vec2::new(1.0, 1.0),
                Vec2::new(0.0, 1.0),
            ]);
        }
        light.emission = Some(checker.clone());
        let scene = Scene::build(&desc(vec![light], vec![])).unwrap();
        let area = 2.0;
        let power = (c0 + c1) * 0.5 * (std::f32::consts::PI * area);
        let mut rng = rng_for(5, 0, 0);
        let n = 200_000;
        let mut flux = glam::DVec3::ZERO;
        for _ in 0..n {
            let e = scene
                .sample_emission(rng.next_f32(), rng.next_2d(), rng.next_2d(), None)
                .unwrap();
            flux += e.flux.as_dvec3();
        }
        let flux = (flux / n as f64).as_vec3();
        assert!(
            ((flux - power) / power).abs().max_element() < 0.01,
            "{flux} vs {power}"
        );
        // Irradiance at a point below the light, off-centre.
        let p = Vec3::new(0.3, 0.0, 0.1);
        let mut e_nee = glam::DVec3::ZERO;
        for _ in 0..n {
            if let Some(ls) = scene.sample_li(p, Vec3::ZERO, rng.next_f32(), rng.next_2d()) {
                e_nee += (ls.weight * ls.wi.y.max(0.0)).as_dvec3();
            }
        }
        let e_nee = (e_nee / n as f64).as_vec3();
        let (nx, nz) = (400, 200);
        let mut e_quad = Rgb::ZERO;
        for i in 0..nx {
            for j in 0..nz {
                let (u, v) = ((i as f32 + 0.5) / nx as f32, (j as f32 + 0.5) / nz as f32);
                let q = Vec3::new(-1.0 + 2.0 * u, 1.0, -0.5 + v);
                let d = q - p;
                let r2 = d.length_squared();
                let cos = d.y / r2.sqrt();
                e_quad += checker.eval(Vec2::new(u, v)) * (cos * cos / r2);
            }
        }
        e_quad *= area / (nx * nz) as f32;
        assert!(
            ((e_nee - e_quad) / e_quad).abs().max_element() < 0.01,
            "{e_nee} vs {e_quad}"
        );
        // Seen from below, the light shows its texture.
        for uv in [
            Vec2::new(0.1, 0.1),
            Vec2::new(0.4, 0.1),
            Vec2::new(0.9, 0.8),
        ] {
            let q = Vec3::new(-1.0 + 2.0 * uv.x, 1.0, -0.5 + uv.y);
            let si = scene
                .intersect(&Ray::new(Vec3::new(q.x, 0.0, q.z), Vec3::Y))
                .unwrap();
            assert_eq!(scene.emitted(&si, -Vec3::Y), checker.eval(uv), "{uv}");
        }
    }
}
