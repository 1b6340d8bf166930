//! `<medium>` (`homogeneous`, `heterogeneous`) with its `<phase>` (`isotropic`, `hg`,
//! `rayleigh`, `tabphase`, `blendphase`) and
//! `<volume>`s (`gridvolume`, `constvolume`), in Mitsuba 3's parameter names and defaults, and
//! the media a shape or the sensor refers to.

use super::props::Props;
use super::{Builder, Element, SceneError};
use crate::parity::media::grid::{read_vol, unit_cube_bounds, GridFilter, VolumeGrid};
use crate::parity::media::phase::{BlendPhase, TabulatedPhase};
use crate::parity::media::{
    Density, Heterogeneous, Medium, MediumInterface, PhaseFunction, VolumeTexture,
};
use crate::spectrum::{Rgb, SpectrumKind};
use std::sync::Arc;

/// The medium plugins this importer knows.
const MEDIUM_PLUGINS: [&str; 2] = ["homogeneous", "heterogeneous"];

/// A world-space box (min, max).
pub(super) type Bounds = (glam::Vec3, glam::Vec3);

/// The volume plugins this importer knows.
const VOLUME_PLUGINS: [&str; 2] = ["gridvolume", "constvolume"];

/// The phase-function plugins this importer knows.
const PHASE_PLUGINS: [&str; 5] = ["isotropic", "hg", "rayleigh", "tabphase", "blendphase"];

/// Builds the medium declared by a `<medium>` element:
/// * `sigma_t` (float or spectrum, default 1; `heterogeneous`: also a `<volume>`): extinction
///   per unit of distance;
/// * `albedo` (float or spectrum, default 0.75; `heterogeneous`: also a `<volume>`):
///   single-scattering albedo;
/// * `scale` (float, default 1): multiplies `sigma_t`;
/// * `sample_emitters` (boolean, default true): light sampling at scattering points;
/// * `has_spectral_extinction` (boolean): accepted; how distances are sampled does not change
///   the image here;
/// * a nested `<phase>` (default `isotropic`).
pub(super) fn build_medium<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<Medium, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if !MEDIUM_PLUGINS.contains(&kind) {
        return Err(el.error(format!(
            "unsupported medium \"{kind}\" (supported media: {})",
            MEDIUM_PLUGINS.join(", ")
        )));
    }
    let mut p = Props::parse(b, el)?;
    let sigma_el = p.element_of("sigma_t");
    let albedo_el = p.element_of("albedo");
    let heterogeneous = kind == "heterogeneous";
    // A plain value is Mitsuba's `constvolume` over the unit cube.
    let volume = |b: &mut Builder<'a>, p: &mut Props<'a>, name, kind, default| match p.object(name)
    {
        Some(o) if heterogeneous => b.volume_value(o, kind),
        Some(o) => Err(o.error(format!(
            "a homogeneous medium's \"{name}\" is a constant: use a heterogeneous medium for a \
             <volume>"
        ))),
        None => Ok((
            VolumeTexture::Constant(
                p.constant_color(b, name, kind)?
                    .unwrap_or(Rgb::splat(default)),
            ),
            (glam::Vec3::ZERO, glam::Vec3::ONE),
        )),
    };
    let (sigma_t, sigma_t_box) = volume(b, &mut p, "sigma_t", SpectrumKind::Unbounded, 1.0)?;
    let (albedo, _) = volume(b, &mut p, "albedo", SpectrumKind::Reflectance, 0.75)?;
    let scale_el = p.element_of("scale");
    let scale = p.float_or("scale", 1.0)? as f32;
    let sample_emitters = p.bool_or("sample_emitters", true)?;
    p.bool_or("has_spectral_extinction", true)?;
    let mut phase = None;
    for obj in p.objects(&["phase", "ref"]) {
        if phase.is_some() {
            return Err(obj.error("a medium can have only one phase function"));
        }
        phase = Some(phase_value(b, obj, "a medium")?);
    }
    p.finish(b)?;
    if !(scale.is_finite() && scale >= 0.0) {
        return Err(scale_el.error(format!("\"scale\" must be finite and >= 0, got {scale}")));
    }
    if !(sigma_t.min() >= 0.0 && (sigma_t.max() * scale).is_finite()) {
        return Err(sigma_el.error(format!(
            "\"sigma_t\" must be finite and >= 0, got values from {} to {}",
            sigma_t.min(),
            sigma_t.max()
        )));
    }
    if let VolumeTexture::Constant(a) = albedo {
        if a.max_element() > 1.0 || a.min_element() < 0.0 {
            return Err(albedo_el.error(format!("\"albedo\" must lie in [0, 1], got {a:?}")));
        }
    }
    let density = match (heterogeneous, sigma_t, albedo) {
        (false, VolumeTexture::Constant(sigma_t), VolumeTexture::Constant(albedo)) => {
            Density::Homogeneous {
                sigma_t: sigma_t * scale,
                albedo,
            }
        }
        // As in Mitsuba, the medium is empty outside its `sigma_t` volume's box — also for a
        // constant one (the unit cube, or a `constvolume`'s `to_world` of it).
        (_, sigma_t, albedo) => Density::Heterogeneous(Box::new(Heterogeneous::new(
            sigma_t,
            albedo,
            scale,
            Some(sigma_t_box),
        ))),
    };
    let name = el
        .attr("id")
        .map(str::to_owned)
        .unwrap_or_else(|| format!("{kind}#{}", b.media.len()));
    Ok(Medium {
        density,
        phase: phase.unwrap_or(PhaseFunction::Isotropic),
        sample_emitters,
        name,
    })
}

/// Builds a `<volume>`:
/// * `gridvolume`: `filename` (a `.vol` grid, 1 or 3 channels, values as stored — `raw` is
///   accepted, an RGB renderer converts nothing), `filter_type` (`trilinear`, `nearest`),
///   `wrap_mode` (`clamp`, `repeat`, `mirror`), `to_world`, `use_grid_bbox`; `accel` and
///   `max_value` are accepted (the majorant is the data's maximum);
/// * `constvolume`: `value` (float or spectrum, default 1), `to_world`.
///
/// Returns the volume and the world-space box it covers (a heterogeneous medium is empty outside
/// its `sigma_t` volume's box, as in Mitsuba).
pub(super) fn build_volume<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
    kind: SpectrumKind,
) -> Result<(VolumeTexture, Bounds), SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let plugin = el.attr("type").unwrap_or_default();
    let mut p = Props::parse(b, el)?;
    let volume = match plugin {
        "constvolume" => {
            let value = p.constant_color(b, "value", kind)?.unwrap_or(Rgb::ONE);
            let to_world = p.transform("to_world")?.unwrap_or(glam::Mat4::IDENTITY);
            (VolumeTexture::Constant(value), unit_cube_bounds(to_world))
        }
        "gridvolume" => {
            let file_el = p.element_of("filename");
            let Some(filename) = p.string("filename")? else {
                return Err(el.error("missing parameter \"filename\""));
            };
            let filter_el = p.element_of("filter_type");
            let filter = match p.string("filter_type")?.unwrap_or("trilinear") {
                "trilinear" => GridFilter::Trilinear,
                "nearest" => GridFilter::Nearest,
                other => {
                    return Err(filter_el.error(format!(
                        "unknown filter_type \"{other}\" (use \"trilinear\" or \"nearest\")"
                    )))
                }
            };
            let wrap = super::textures::wrap_mode(&mut p, "clamp")?;
            let to_world_el = p.element_of("to_world");
            let to_world = p.transform("to_world")?.unwrap_or(glam::Mat4::IDENTITY);
            let use_grid_bbox = p.bool_or("use_grid_bbox", false)?;
            p.bool_or("raw", false)?;
            p.bool_or("accel", true)?;
            p.ignore(
                b,
                &["max_value"],
                "the majorant is the maximum of the grid's values",
            );
            let path = file_el.resolve_path(filename, &b.diag.search_paths);
            let file = read_vol(&path).map_err(|m| {
                file_el.error(format!("cannot load volume \"{}\": {m}", path.display()))
            })?;
            let grid = VolumeGrid::new(
                file,
                to_world,
                use_grid_bbox,
                filter,
                wrap,
                path.display().to_string(),
            )
            .map_err(|m| to_world_el.error(format!("volume \"{}\": {m}", path.display())))?;
            let bounds = grid.bounds;
            (VolumeTexture::Grid(Arc::new(grid)), bounds)
        }
        _ => {
            return Err(el.error(format!(
                "unsupported volume \"{plugin}\" (supported volumes: {})",
                VOLUME_PLUGINS.join(", ")
            )))
        }
    };
    p.finish(b)?;
    Ok(volume)
}

/// The phase function declared by `obj` (a nested `<phase>` or a `<ref>` to one) inside
/// `owner` (for the message when it is something else).
fn phase_value<'a>(
    b: &mut Builder<'a>,
    obj: &'a Element,
    owner: &str,
) -> Result<PhaseFunction, SceneError> {
    let target = b.deref(obj)?;
    if target.tag != "phase" {
        return Err(obj.error(format!(
            "{owner} holds a <phase>, not {}",
            target.describe()
        )));
    }
    build_phase(b, target)
}

/// Builds a `<phase>`:
/// * `isotropic`, `rayleigh`;
/// * `hg`: `g` (default 0.8) in (−1, 1);
/// * `tabphase`: `values`, a string of at least two comma- or space-separated non-negative
///   numbers, not all zero, at cosines of the scattering angle regularly spaced from −1 to 1
///   (1: forward scattering), normalised;
/// * `blendphase`: `weight` (float or `<volume>`, default 0.5, clamped to [0, 1]) and exactly
///   two nested phase functions, in file order: weight 0 is the first, 1 the second.
pub(super) fn build_phase<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<PhaseFunction, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    let mut p = Props::parse(b, el)?;
    let phase = match kind {
        "isotropic" => PhaseFunction::Isotropic,
        "rayleigh" => PhaseFunction::Rayleigh,
        "hg" => {
            let g_el = p.element_of("g");
            let g = p.float_or("g", 0.8)?;
            if !(g > -1.0 && g < 1.0) {
                return Err(g_el.error(format!("\"g\" must lie in (-1, 1), got {g}")));
            }
            PhaseFunction::HenyeyGreenstein { g: g as f32 }
        }
        "tabphase" => {
            let values_el = p.element_of("values");
            let Some(text) = p.string("values")? else {
                return Err(el.error("missing parameter \"values\""));
            };
            let values = text
                .split([',', ' ', '\t', '\n', '\r'])
                .filter(|t| !t.is_empty())
                .map(|t| {
                    t.parse::<f32>().map_err(|_| {
                        values_el.error(format!("\"values\": \"{t}\" is not a number"))
                    })
                })
                .collect::<Result<Vec<f32>, SceneError>>()?;
            let table = TabulatedPhase::new(values)
                .map_err(|m| values_el.error(format!("\"values\": {m}")))?;
            PhaseFunction::Tabulated(std::sync::Arc::new(table))
        }
        "blendphase" => {
            let weight_el = p.element_of("weight");
            let weight = match p.object("weight") {
                Some(o) => b.volume_value(o, SpectrumKind::Unbounded)?.0,
                None => VolumeTexture::Constant(Rgb::splat(p.float_or("weight", 0.5)? as f32)),
            };
            if weight.min().is_nan() || weight.max().is_nan() {
                return Err(weight_el.error("\"weight\" is not a number"));
            }
            let nested = p
                .objects(&["phase", "ref"])
                .into_iter()
                .map(|o| phase_value(b, o, "a blendphase"))
                .collect::<Result<Vec<_>, _>>()?;
            let nested: [PhaseFunction; 2] = nested.try_into().map_err(|v: Vec<_>| {
                el.error(format!(
                    "a blendphase needs exactly two nested phase functions, got {}",
                    v.len()
                ))
            })?;
            PhaseFunction::Blend(std::sync::Arc::new(BlendPhase { weight, nested }))
        }
        _ => {
            return Err(el.error(format!(
                "unsupported phase function \"{kind}\" (supported: {})",
                PHASE_PLUGINS.join(", ")
            )))
        }
    };
    p.finish(b)?;
    Ok(phase)
}

/// Where a medium sits relative to the plugin that names it.
pub(super) enum MediumRole {
    /// A shape's `interior`.
    Interior,
    /// A shape's `exterior`.
    Exterior,
}

/// The role of a medium `obj` (a nested `<medium>` or a `<ref>` to one) inside a shape, by the
/// `name` it is given there, as Mitsuba 3.
pub(super) fn shape_medium_role(obj: &Element) -> Result<MediumRole, SceneError> {
    match obj.attr("name") {
        Some("interior") => Ok(MediumRole::Interior),
        Some("exterior") => Ok(MediumRole::Exterior),
        other => Err(obj.error(format!(
            "a medium inside a shape must be named \"interior\" or \"exterior\"{}",
            match other {
                Some(n) => format!(", not \"{n}\""),
                None => String::new(),
            }
        ))),
    }
}

/// Records medium `index` in `interface` for `role`; a second medium for one side is an error.
pub(super) fn set_side(
    interface: &mut MediumInterface,
    role: MediumRole,
    index: u32,
    obj: &Element,
) -> Result<(), SceneError> {
    let (slot, side) = match role {
        MediumRole::Interior => (&mut interface.interior, "interior"),
        MediumRole::Exterior => (&mut interface.exterior, "exterior"),
    };
    if slot.is_some() {
        return Err(obj.error(format!("a shape can have only one {side} medium")));
    }
    *slot = Some(index);
    Ok(())
}
