//! `<medium>` (`homogeneous`) with its `<phase>` (`isotropic`, `hg`), in Mitsuba 3's parameter
//! names and defaults, and the media a shape or the sensor refers to.

use super::props::Props;
use super::{Builder, Element, SceneError};
use crate::media::{Medium, MediumInterface, PhaseFunction};
use crate::spectrum::{Rgb, SpectrumKind};

/// The medium plugins this importer knows.
const MEDIUM_PLUGINS: [&str; 1] = ["homogeneous"];

/// The phase-function plugins this importer knows.
const PHASE_PLUGINS: [&str; 2] = ["isotropic", "hg"];

/// Builds the medium declared by a `<medium>` element:
/// * `sigma_t` (float or spectrum, default 1): extinction per unit of distance;
/// * `albedo` (float or spectrum, default 0.75): single-scattering albedo (constant only);
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
    let sigma_t = p
        .constant_color(b, "sigma_t", SpectrumKind::Unbounded)?
        .unwrap_or(Rgb::ONE);
    let albedo_el = p.element_of("albedo");
    let albedo = p
        .constant_color(b, "albedo", SpectrumKind::Reflectance)?
        .unwrap_or(Rgb::splat(0.75));
    let scale_el = p.element_of("scale");
    let scale = p.float_or("scale", 1.0)? as f32;
    let sample_emitters = p.bool_or("sample_emitters", true)?;
    p.bool_or("has_spectral_extinction", true)?;
    let mut phase = None;
    for obj in p.objects(&["phase", "ref"]) {
        let target = b.deref(obj)?;
        if target.tag != "phase" {
            return Err(obj.error(format!(
                "a medium holds a <phase>, not {}",
                target.describe()
            )));
        }
        if phase.is_some() {
            return Err(obj.error("a medium can have only one phase function"));
        }
        phase = Some(build_phase(b, target)?);
    }
    p.finish(b)?;
    if !(scale.is_finite() && scale >= 0.0) {
        return Err(scale_el.error(format!("\"scale\" must be finite and >= 0, got {scale}")));
    }
    let sigma_t = sigma_t * scale;
    if !(sigma_t.is_finite() && sigma_t.min_element() >= 0.0) {
        return Err(sigma_el.error(format!(
            "\"sigma_t\" must be finite and >= 0, got {sigma_t:?}"
        )));
    }
    if albedo.max_element() > 1.0 || albedo.min_element() < 0.0 {
        return Err(albedo_el.error(format!("\"albedo\" must lie in [0, 1], got {albedo:?}")));
    }
    let name = el
        .attr("id")
        .map(str::to_owned)
        .unwrap_or_else(|| format!("{kind}#{}", b.media.len()));
    Ok(Medium {
        sigma_t,
        albedo,
        phase: phase.unwrap_or(PhaseFunction::Isotropic),
        sample_emitters,
        name,
    })
}

/// Builds a `<phase>`: `isotropic`, or `hg` with `g` (default 0.8) in (−1, 1).
fn build_phase<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<PhaseFunction, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    let mut p = Props::parse(b, el)?;
    let phase = match kind {
        "isotropic" => PhaseFunction::Isotropic,
        "hg" => {
            let g_el = p.element_of("g");
            let g = p.float_or("g", 0.8)?;
            if !(g > -1.0 && g < 1.0) {
                return Err(g_el.error(format!("\"g\" must lie in (-1, 1), got {g}")));
            }
            PhaseFunction::HenyeyGreenstein { g: g as f32 }
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
