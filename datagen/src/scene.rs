//! One generated scene: its id, family and Mitsuba 3 XML with PLY meshes and image files
//! (textures), plus the builder the family generators use to assemble shapes, materials, lights
//! and the camera.

use crate::config::Config;
use crate::ply::{encode_ply, Mesh};
use crate::xml::{document, fmt_f32, Element};
use glam::{Mat3, Mat4, Vec3};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

/// The scene families, in generation order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Rooms lit mostly indirectly.
    Room,
    /// Refractive caustics from glass objects.
    Glass,
    /// Water surfaces over textured floors.
    Water,
    /// Reflective caustics from metal rings and mirrors.
    Metal,
    /// Depth-of-field shelves.
    Shelf,
    /// Furnished rooms lit by small visible lamps with shades.
    Lamp,
    /// Glass and liquid objects on a table, optionally before a mirror.
    Tabletop,
    /// Sun- and sky-lit exteriors with caustics on the ground.
    Exterior,
    /// Procedural meshes with random materials of every BSDF kind.
    Material,
    /// Bitmap-textured, bump- and normal-mapped surfaces (room corners, table tops).
    Textured,
    /// Scenes the user brings (`[families.external]`), not generated.
    External,
}

impl Family {
    /// All families in generation order.
    pub const ALL: [Family; 11] = [
        Family::Room,
        Family::Glass,
        Family::Water,
        Family::Metal,
        Family::Shelf,
        Family::Lamp,
        Family::Tabletop,
        Family::Exterior,
        Family::Material,
        Family::Textured,
        Family::External,
    ];

    /// Lower-case name used in ids, the manifest and the config.
    pub fn name(self) -> &'static str {
        match self {
            Family::Room => "room",
            Family::Glass => "glass",
            Family::Water => "water",
            Family::Metal => "metal",
            Family::Shelf => "shelf",
            Family::Lamp => "lamp",
            Family::Tabletop => "tabletop",
            Family::Exterior => "exterior",
            Family::Material => "material",
            Family::Textured => "textured",
            Family::External => "external",
        }
    }
}

/// A generated scene ready to be written: `scene.xml` plus its PLY and image files.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedScene {
    /// Scene id, e.g. `007-glass`.
    pub id: String,
    /// Its family.
    pub family: Family,
    /// Mitsuba 3 XML text of `scene.xml`.
    pub xml: String,
    /// PLY meshes as (file name relative to the XML, mesh).
    pub meshes: Vec<(String, Mesh)>,
    /// Image files (encoded, e.g. PNG textures) as (file name relative to the XML, bytes); a
    /// deterministic function of the scene like everything else.
    pub images: Vec<(String, Vec<u8>)>,
}

impl GeneratedScene {
    /// All files of the scene as (file name, bytes), `scene.xml` first, then the meshes and
    /// the images.
    pub fn files(&self) -> Vec<(String, Vec<u8>)> {
        let mut out = vec![("scene.xml".to_owned(), self.xml.clone().into_bytes())];
        for (name, mesh) in &self.meshes {
            out.push((name.clone(), encode_ply(mesh)));
        }
        out.extend(self.images.iter().cloned());
        out
    }
}

/// A diffuse, glossy, metallic or glass material.
#[derive(Debug, Clone, PartialEq)]
pub enum Material {
    /// Lambertian with a constant albedo.
    Diffuse([f32; 3]),
    /// Lambertian with a checkerboard (two albedos, `checks` squares per unit of uv).
    Checker {
        /// Albedo of `color0`.
        a: [f32; 3],
        /// Albedo of `color1`.
        b: [f32; 3],
        /// uv scale (Mitsuba's checkerboard has 2 squares per unit uv).
        uv_scale: f32,
    },
    /// Coated diffuse; `alpha` < 0.01 is written as smooth `plastic`.
    Plastic {
        /// Diffuse albedo under the coat.
        albedo: [f32; 3],
        /// GGX roughness of the coat.
        alpha: f32,
    },
    /// Named metal (`Au`, `Cu`, `Al`, ...); `alpha` < 0.01 is written as smooth `conductor`.
    Metal {
        /// Mitsuba material name.
        name: String,
        /// GGX roughness.
        alpha: f32,
    },
    /// Smooth glass or water.
    Glass {
        /// Interior index of refraction (exterior is air).
        ior: f32,
    },
    /// Frosted glass (`roughdielectric`, GGX).
    RoughGlass {
        /// Interior index of refraction (exterior is air).
        ior: f32,
        /// GGX roughness.
        alpha: f32,
    },
    /// Mitsuba's `principled` BSDF; `checker` = (second colour, uv scale) makes the base colour
    /// a checkerboard of `base` and that colour.
    Principled {
        /// Base colour.
        base: [f32; 3],
        /// Optional checkerboard partner of `base` and its uv scale.
        checker: Option<([f32; 3], f32)>,
        /// Roughness in [0, 1].
        roughness: f32,
        /// Metallic in [0, 1].
        metallic: f32,
        /// Clear coat in [0, 1].
        clearcoat: f32,
    },
    /// A `<bsdf>` element the family built itself (textured, bump- or normal-mapped models,
    /// whose images the scene carries: [`SceneBuilder::image`]).
    Xml(Element),
}

/// A `checkerboard` texture named `name` of albedos `a` (`color0`) and `b` (`color1`).
fn checkerboard(name: &str, a: [f32; 3], b: [f32; 3], uv_scale: f32) -> Element {
    Element::plugin("texture", "checkerboard")
        .attr("name", name)
        .rgb("color0", a)
        .rgb("color1", b)
        .child(
            Element::new("transform").attr("name", "to_uv").child(
                Element::new("scale")
                    .attr("x", fmt_f32(uv_scale))
                    .attr("y", fmt_f32(uv_scale)),
            ),
        )
}

impl Material {
    /// The `<bsdf>` element.
    pub fn element(&self) -> Element {
        match self {
            Material::Diffuse(c) => Element::plugin("bsdf", "diffuse").rgb("reflectance", *c),
            Material::Checker { a, b, uv_scale } => Element::plugin("bsdf", "diffuse")
                .child(checkerboard("reflectance", *a, *b, *uv_scale)),
            Material::Plastic { albedo, alpha } if *alpha < 0.01 => {
                Element::plugin("bsdf", "plastic")
                    .rgb("diffuse_reflectance", *albedo)
                    .float("int_ior", 1.5)
            }
            Material::Plastic { albedo, alpha } => Element::plugin("bsdf", "roughplastic")
                .string("distribution", "ggx")
                .float("alpha", *alpha)
                .rgb("diffuse_reflectance", *albedo)
                .float("int_ior", 1.5),
            Material::Metal { name, alpha } if *alpha < 0.01 => {
                Element::plugin("bsdf", "conductor").string("material", name)
            }
            Material::Metal { name, alpha } => Element::plugin("bsdf", "roughconductor")
                .string("material", name)
                .string("distribution", "ggx")
                .float("alpha", *alpha),
            Material::Glass { ior } => Element::plugin("bsdf", "dielectric")
                .float("int_ior", *ior)
                .float("ext_ior", 1.0),
            Material::RoughGlass { ior, alpha } => Element::plugin("bsdf", "roughdielectric")
                .string("distribution", "ggx")
                .float("alpha", *alpha)
                .float("int_ior", *ior)
                .float("ext_ior", 1.0),
            Material::Principled {
                base,
                checker,
                roughness,
                metallic,
                clearcoat,
            } => {
                let e = Element::plugin("bsdf", "principled");
                let e = match checker {
                    Some((other, uv_scale)) => {
                        e.child(checkerboard("base_color", *base, *other, *uv_scale))
                    }
                    None => e.rgb("base_color", *base),
                };
                e.float("roughness", *roughness)
                    .float("metallic", *metallic)
                    .float("clearcoat", *clearcoat)
            }
            Material::Xml(e) => e.clone(),
        }
    }
}

/// A transform that maps the unit rectangle/cube axes onto `x`, `y`, `z` and moves the origin
/// to `origin`.
pub fn frame(origin: Vec3, x: Vec3, y: Vec3, z: Vec3) -> Mat4 {
    Mat4::from_cols(
        x.extend(0.0),
        y.extend(0.0),
        z.extend(0.0),
        origin.extend(1.0),
    )
}

/// An up vector that is not parallel to `dir`.
pub fn up_for(dir: Vec3) -> Vec3 {
    if dir.normalize().dot(Vec3::Y).abs() > 0.99 {
        Vec3::Z
    } else {
        Vec3::Y
    }
}

/// Direction with the given azimuth (from +x towards +z) and elevation (degrees).
pub fn spherical(azimuth_deg: f32, elevation_deg: f32) -> Vec3 {
    let (a, e) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    Vec3::new(e.cos() * a.cos(), e.sin(), e.cos() * a.sin())
}

/// Accumulates the elements of one scene document.
#[derive(Debug)]
pub struct SceneBuilder {
    elements: Vec<Element>,
    meshes: Vec<(String, Mesh)>,
    images: Vec<(String, Vec<u8>)>,
    width: u32,
    height: u32,
    max_depth: u32,
}

impl SceneBuilder {
    /// An empty scene with the config's film size and path depth.
    pub fn new(config: &Config) -> Self {
        let integrator = Element::plugin("integrator", "path")
            .integer("max_depth", i64::from(config.render.max_depth));
        Self {
            elements: vec![integrator],
            meshes: Vec::new(),
            images: Vec::new(),
            width: config.width,
            height: config.height,
            max_depth: config.render.max_depth,
        }
    }

    /// The configured maximum path depth.
    pub fn max_depth(&self) -> u32 {
        self.max_depth
    }

    /// Adds the camera: a pinhole (`perspective`), or a `thinlens` when `lens` = (aperture
    /// radius, focus distance) is given. `fov` is horizontal, in degrees.
    pub fn camera(&mut self, origin: Vec3, target: Vec3, fov: f32, lens: Option<(f32, f32)>) {
        let kind = if lens.is_some() {
            "thinlens"
        } else {
            "perspective"
        };
        let mut sensor = Element::plugin("sensor", kind)
            .string("fov_axis", "x")
            .float("fov", fov);
        if let Some((radius, focus)) = lens {
            sensor = sensor
                .float("aperture_radius", radius)
                .float("focus_distance", focus);
        }
        sensor = sensor
            .lookat("to_world", origin, target, up_for(target - origin))
            .child(Element::plugin("sampler", "independent").integer("sample_count", 64))
            .child(
                Element::plugin("film", "hdrfilm")
                    .integer("width", i64::from(self.width))
                    .integer("height", i64::from(self.height))
                    .child(Element::plugin("rfilter", "box")),
            );
        self.elements.insert(1, sensor);
    }

    /// A rectangle centred at `center` with half-edge vectors `u`, `v`; its front (normal)
    /// side is `u × v`. `emission` makes it a one-sided area light.
    pub fn rectangle(
        &mut self,
        center: Vec3,
        u: Vec3,
        v: Vec3,
        material: &Material,
        emission: Option<[f32; 3]>,
    ) {
        let n = u.cross(v).normalize();
        let mut shape = Element::plugin("shape", "rectangle")
            .matrix("to_world", frame(center, u, v, n))
            .child(material.element());
        if let Some(radiance) = emission {
            shape = shape.child(Element::plugin("emitter", "area").rgb("radiance", radiance));
        }
        self.elements.push(shape);
    }

    /// A box centred at `center` with half-sizes `half`, rotated by `yaw` degrees about +y.
    pub fn cube(&mut self, center: Vec3, half: Vec3, yaw: f32, material: &Material) {
        let r = Mat3::from_rotation_y(yaw.to_radians());
        let m = frame(
            center,
            r.x_axis * half.x,
            r.y_axis * half.y,
            r.z_axis * half.z,
        );
        self.elements.push(
            Element::plugin("shape", "cube")
                .matrix("to_world", m)
                .child(material.element()),
        );
    }

    /// An analytic sphere.
    pub fn sphere(&mut self, center: Vec3, radius: f32, material: &Material) {
        self.elements.push(
            Element::plugin("shape", "sphere")
                .point("center", center)
                .float("radius", radius)
                .child(material.element()),
        );
    }

    /// A PLY mesh written next to the XML as `<name>.ply`, placed by translation and a yaw.
    pub fn mesh(&mut self, name: &str, mesh: Mesh, offset: Vec3, yaw: f32, material: &Material) {
        let file = format!("{name}.ply");
        let m = Mat4::from_translation(offset) * Mat4::from_rotation_y(yaw.to_radians());
        self.elements.push(
            Element::plugin("shape", "ply")
                .string("filename", &file)
                .matrix("to_world", m)
                .child(material.element()),
        );
        self.meshes.push((file, mesh));
    }

    /// An image file written next to the XML as `name` (a path relative to it, e.g.
    /// `textures/floor.png`), which the scene's textures read.
    pub fn image(&mut self, name: &str, bytes: Vec<u8>) {
        self.images.push((name.to_owned(), bytes));
    }

    /// A spherical area light (a bulb) of radius `radius` emitting `power` (W) in total, tinted
    /// by `color` (scaled so that its green channel carries the power).
    pub fn sphere_light(&mut self, center: Vec3, radius: f32, power: f32, color: [f32; 3]) {
        // Lambertian emitter: power = π · radiance · area, with area 4πr².
        let radiance = power / (PI * 4.0 * PI * radius * radius);
        let scale = radiance / color[1].max(1e-3);
        self.elements.push(
            Element::plugin("shape", "sphere")
                .point("center", center)
                .float("radius", radius)
                .child(Material::Diffuse([0.0; 3]).element())
                .child(
                    Element::plugin("emitter", "area").rgb("radiance", color.map(|c| c * scale)),
                ),
        );
    }

    /// A point light of total power `power` (W).
    pub fn point_light(&mut self, position: Vec3, power: f32) {
        let i = power / (4.0 * PI);
        self.elements.push(
            Element::plugin("emitter", "point")
                .point("position", position)
                .rgb("intensity", [i; 3]),
        );
    }

    /// A spot light at `position` aimed at `target` with the given cutoff (degrees), whose
    /// intensity is set so the emitted power is about `power` (W).
    pub fn spot_light(&mut self, position: Vec3, target: Vec3, power: f32, cutoff: f32) {
        let beam = 0.75 * cutoff;
        // Solid angle of the cone up to the mean of beam and cutoff (smooth falloff between).
        let half = (0.5 * (beam + cutoff)).to_radians();
        let i = power / (2.0 * PI * (1.0 - half.cos()));
        self.elements.push(
            Element::plugin("emitter", "spot")
                .lookat("to_world", position, target, up_for(target - position))
                .rgb("intensity", [i; 3])
                .float("cutoff_angle", cutoff)
                .float("beam_width", beam),
        );
    }

    /// A one-sided square area light of half-size `half` at `position`, facing `target`,
    /// emitting `power` (W) in total.
    pub fn area_light(&mut self, position: Vec3, target: Vec3, half: f32, power: f32) {
        let n = (target - position).normalize();
        let u = n.cross(up_for(n)).normalize() * half;
        let v = n.cross(u).normalize() * half;
        // Front side is u × v, which must equal +n: u × (n × u) = n |u|².
        let radiance = power / (PI * 4.0 * half * half);
        self.rectangle(
            position,
            u,
            v,
            &Material::Diffuse([0.0; 3]),
            Some([radiance; 3]),
        );
    }

    /// A directional light (sun) travelling along `direction`.
    pub fn sun(&mut self, direction: Vec3, irradiance: f32) {
        self.elements.push(
            Element::plugin("emitter", "directional")
                .vector("direction", direction.normalize())
                .rgb("irradiance", [irradiance; 3]),
        );
    }

    /// A constant environment (skipped when `radiance` ≤ 0).
    pub fn environment(&mut self, radiance: f32) {
        if radiance > 0.0 {
            self.elements
                .push(Element::plugin("emitter", "constant").rgb("radiance", [radiance; 3]));
        }
    }

    /// Finishes the scene.
    pub fn finish(self, id: String, family: Family, comment: &str) -> GeneratedScene {
        GeneratedScene {
            xml: document(comment, self.elements),
            id,
            family,
            meshes: self.meshes,
            images: self.images,
        }
    }
}

/// Writes the scene's files into `dir` (created if needed), each atomically and only when its
/// bytes differ from what is there, so concurrent shards and reruns agree. Returns the XML path.
pub fn write_scene_files(
    scene: &GeneratedScene,
    dir: &std::path::Path,
) -> std::io::Result<std::path::PathBuf> {
    for (name, bytes) in scene.files() {
        crate::fsutil::write_if_changed(&dir.join(&name), &bytes).map_err(|e| {
            std::io::Error::new(e.kind(), format!("{}: {e}", dir.join(&name).display()))
        })?;
    }
    Ok(dir.join("scene.xml"))
}
