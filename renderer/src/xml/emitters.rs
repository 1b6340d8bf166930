//! `<emitter>` plugins: `area` and `directionalarea` (inside a shape), `point`, `spot`,
//! `projector`, `directional`, `constant`, `envmap`.
//! Emission spectra are converted without D65 weighting, as Mitsuba's RGB variants do.

use super::props::Props;
use super::{Builder, Element, SceneError};
use crate::description::EmitterDesc;
use crate::lights::{EnvmapError, EnvmapLight};
use crate::spectrum::{Rgb, SpectrumKind};
use crate::texture::Texture;
use glam::{Mat3, Mat4, Vec3};

const EMISSION: SpectrumKind = SpectrumKind::Emission;

/// Builds a top-level (not shape-attached) emitter and adds it to the scene.
pub(super) fn build_emitter<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<(), SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if kind == "area" || kind == "directionalarea" {
        let article = if kind == "area" { "an" } else { "a" };
        return Err(el.error(format!(
            "{article} {kind} emitter must be nested inside a <shape>"
        )));
    }
    if ![
        "point",
        "spot",
        "projector",
        "directional",
        "constant",
        "envmap",
    ]
    .contains(&kind)
    {
        let err = el.error(format!(
            "unknown plugin \"{kind}\" (supported emitters: area, directionalarea, point, spot, projector, directional, constant, envmap)"
        ));
        return b.diag.unknown(err);
    }
    let mut p = Props::parse(b, el)?;
    let emitter = match kind {
        "point" => {
            let intensity = color(b, &mut p, "intensity")?;
            let to_world = p.transform("to_world")?;
            let position = p.vector("position")?;
            let position = match (position, to_world) {
                (Some(_), Some(_)) => {
                    return Err(el.error("give either \"position\" or \"to_world\", not both"))
                }
                (Some(pos), None) => pos,
                (None, Some(m)) => m.transform_point3(Vec3::ZERO),
                (None, None) => Vec3::ZERO,
            };
            EmitterDesc::Point {
                position,
                intensity,
            }
        }
        "spot" => {
            let intensity = color(b, &mut p, "intensity")?;
            let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
            let cutoff_angle = p.float_or("cutoff_angle", 20.0)?;
            let beam_width = p.float_or("beam_width", cutoff_angle * 0.75)?;
            if !(cutoff_angle > 0.0 && cutoff_angle <= 180.0) {
                return Err(p.element_of("cutoff_angle").error(format!(
                    "cutoff_angle must be in (0, 180], got {cutoff_angle}"
                )));
            }
            if beam_width.is_nan() || beam_width <= 0.0 {
                return Err(p
                    .element_of("beam_width")
                    .error(format!("beam_width must be positive, got {beam_width}")));
            }
            // Mitsuba: a texture projected along the beam; it must vary (a bitmap, a
            // checkerboard; a mesh_attribute is refused where it is read: no mesh here).
            let texture_el = p.element_of("texture");
            let texture = p.texture(b, "texture", SpectrumKind::Reflectance)?;
            match &texture {
                Some(Texture::Constant(_)) => {
                    return Err(texture_el.error(
                        "the parameter \"texture\" must be spatially varying (e.g. a bitmap), as in Mitsuba",
                    ))
                }
                Some(t) if !t.is_finite_non_negative() => {
                    return Err(texture_el.error(
                        "\"texture\" must be finite and non-negative (a texel is not)",
                    ))
                }
                _ => {}
            }
            EmitterDesc::Spot {
                to_world,
                intensity,
                cutoff_angle: cutoff_angle as f32,
                beam_width: beam_width.min(cutoff_angle) as f32,
                texture,
            }
        }
        "projector" => {
            let irradiance_el = p.element_of("irradiance");
            let irradiance = p.texture_or(b, "irradiance", EMISSION, 1.0)?;
            if !irradiance.is_finite_non_negative() {
                return Err(irradiance_el
                    .error("\"irradiance\" must be finite and non-negative (a value is not)"));
            }
            let scale_el = p.element_of("scale");
            let scale = p.float_or("scale", 1.0)?;
            if scale < 0.0 {
                return Err(scale_el.error(format!("\"scale\" must not be negative, got {scale}")));
            }
            let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
            // The perspective camera's field of view, over the image's aspect ratio (Mitsuba:
            // the texture's resolution; 1 × 1 for a constant).
            let (fov, axis) = super::sensors::parse_fov(&mut p)?;
            let aspect = irradiance.aspect_ratio();
            EmitterDesc::Projector {
                to_world,
                irradiance,
                scale: scale as f32,
                fov_x: crate::camera::horizontal_fov(fov as f32, axis, aspect),
            }
        }
        "directional" => {
            let irradiance = color(b, &mut p, "irradiance")?;
            let to_world = p.transform("to_world")?;
            let direction = p.vector("direction")?;
            let direction = match (direction, to_world) {
                (Some(_), Some(_)) => {
                    return Err(el.error("give either \"direction\" or \"to_world\", not both"))
                }
                (Some(d), None) => d,
                (None, Some(m)) => m.transform_vector3(Vec3::Z),
                (None, None) => Vec3::Z,
            };
            let Some(direction) = direction.try_normalize() else {
                return Err(el.error("the light direction is zero"));
            };
            EmitterDesc::Directional {
                direction,
                irradiance,
            }
        }
        "envmap" => {
            let file_el = p.element_of("filename");
            let Some(filename) = p.string("filename")? else {
                return Err(el.error("missing parameter \"filename\""));
            };
            let scale_el = p.element_of("scale");
            let scale = p.float("scale")?.unwrap_or(1.0) as f32;
            let to_world_el = p.element_of("to_world");
            let to_world = Mat3::from_mat4(p.transform("to_world")?.unwrap_or(Mat4::IDENTITY));
            let image = super::textures::load_bitmap(b, file_el, filename, false)?;
            let path = file_el.resolve_path(filename, &b.diag.search_paths);
            match EnvmapLight::check(&image, to_world, scale) {
                Ok(()) => {}
                Err(e @ EnvmapError::BadScale(_)) => return Err(scale_el.error(e.to_string())),
                Err(e @ EnvmapError::NotARotation) => return Err(to_world_el.error(e.to_string())),
                Err(e) => return Err(file_el.error(format!("envmap \"{}\": {e}", path.display()))),
            }
            p.ignore(
                b,
                &["mis_compensation"],
                "the map is sampled by its own luminance (changes noise only, not the image)",
            );
            EmitterDesc::Envmap {
                image,
                to_world,
                scale,
                filename: path,
            }
        }
        _ => EmitterDesc::Constant {
            radiance: color(b, &mut p, "radiance")?,
        },
    };
    p.ignore(
        b,
        &["sampling_weight"],
        "lights are sampled proportionally to their power",
    );
    // The medium an emitter sits in (Mitsuba: any name) is built, so its errors are reported,
    // but not needed: `volpath`'s shadow rays track the media from the shading point.
    for obj in p.objects(&["medium", "ref"]) {
        let target = b.deref(obj)?;
        if target.tag != "medium" {
            return Err(obj.error(format!(
                "unexpected {} inside an emitter",
                target.describe()
            )));
        }
        b.medium_index(obj)?;
    }
    p.finish(b)?;
    b.emitters.push(emitter);
    Ok(())
}

/// The radiance of an `area` or `directionalarea` emitter nested in a shape, and whether it
/// is the latter (collimated: the radiance leaves only along the surface normal, Mitsuba's
/// "similar to an area light, but emitting only in the normal direction").
pub(super) fn area_radiance<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<Option<(Texture, bool)>, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if kind != "area" && kind != "directionalarea" {
        let err = el.error(format!("unknown plugin \"{kind}\" inside a shape (only \"area\" and \"directionalarea\" emitters can be attached to shapes)"));
        b.diag.unknown(err)?;
        return Ok(None);
    }
    let mut p = Props::parse(b, el)?;
    // A colour, or a texture over the shape's uvs (Mitsuba accepts both).
    let radiance_el = p.element_of("radiance");
    let radiance = p
        .texture(b, "radiance", EMISSION)?
        .unwrap_or(Texture::Constant(Rgb::ONE));
    if !radiance.is_finite_non_negative() {
        return Err(radiance_el.error(
            "\"radiance\" must be finite and non-negative (a texel of its texture is not)",
        ));
    }
    p.ignore(
        b,
        &["sampling_weight"],
        "lights are sampled proportionally to their power",
    );
    p.finish(b)?;
    Ok(Some((radiance, kind == "directionalarea")))
}

/// An emission colour parameter (default 1, as Mitsuba), constant and non-negative.
fn color<'a>(b: &mut Builder<'a>, p: &mut Props<'a>, name: &str) -> Result<Rgb, SceneError> {
    let el = p.element_of(name);
    let c = p.constant_color(b, name, EMISSION)?.unwrap_or(Rgb::ONE);
    if c.min_element() < 0.0 {
        return Err(el.error(format!("\"{name}\" must not be negative")));
    }
    Ok(c)
}
