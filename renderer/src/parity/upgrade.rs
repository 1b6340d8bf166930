//! Scene files written for Mitsuba before version 2 (`<scene version="0.6.0">`), read as
//! Mitsuba 3 reads them (its parser's `upgrade_from_v1`): parameter names in camelCase become
//! snake_case (`intIOR` → `int_ior`, `toWorld` → `to_world`), a diffuse BSDF's
//! `diffuse_reflectance` is its `reflectance`, and a texture's `uoffset` / `voffset` / `uscale` /
//! `vscale` become its `to_uv` transform. Plugin names are not translated (nor are they by
//! Mitsuba 3): a plugin that no longer exists is an unknown plugin.

use crate::xml::{Element, SceneError};

/// Whether a file of scene `version` ("major.minor.patch") predates Mitsuba 2's names.
pub(crate) fn is_legacy(version: &str) -> bool {
    version
        .split('.')
        .next()
        .and_then(|major| major.trim().parse::<u32>().ok())
        .is_some_and(|major| major < 2)
}

/// A camelCase parameter name in snake_case, as Mitsuba 3 converts it: an underscore where a
/// lower-case letter is followed by an upper-case one, and that run of capitals lowered
/// (`intIOR` → `int_ior`, `specularReflectance` → `specular_reflectance`; `IOR` stays).
pub(crate) fn snake_case(name: &str) -> String {
    let chars: Vec<char> = name.chars().collect();
    let mut out = String::with_capacity(name.len() + 4);
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if i > 0 && chars[i - 1].is_ascii_lowercase() && c.is_ascii_uppercase() {
            out.push('_');
            out.push(c.to_ascii_lowercase());
            while i + 1 < chars.len() && chars[i + 1].is_ascii_uppercase() {
                i += 1;
                out.push(chars[i].to_ascii_lowercase());
            }
        } else {
            out.push(c);
        }
        i += 1;
    }
    out
}

/// Renames the `name` attribute of a parameter or nested plugin of a legacy file.
pub(crate) fn rename_parameter(el: &mut Element) {
    // `<default name>` names a `$` parameter of the file, not a plugin parameter.
    if el.tag == "default" {
        return;
    }
    if let Some(name) = el.attr("name") {
        let renamed = snake_case(name);
        set_name(el, &renamed);
    }
}

/// The plugin-level upgrades of a legacy file's element whose parameters are already renamed.
pub(crate) fn upgrade_plugin(el: &mut Element) -> Result<(), SceneError> {
    let named = |el: &Element, name: &str| {
        el.children
            .iter()
            .position(|c| c.attr("name") == Some(name))
    };
    if el.tag == "bsdf" && el.attr("type") == Some("diffuse") {
        if let Some(i) = named(el, "diffuse_reflectance") {
            set_name(&mut el.children[i], "reflectance");
        }
    }
    // uoffset, voffset, uscale, vscale → to_uv = scale · translate (the offset applies first).
    let mut values = [
        ("uoffset", "0"),
        ("voffset", "0"),
        ("uscale", "1"),
        ("vscale", "1"),
    ]
    .map(|(name, default)| (name, default.to_owned()));
    let mut first = None;
    for (name, value) in &mut values {
        let Some(i) = named(el, name) else {
            continue;
        };
        let child = &el.children[i];
        if child.tag != "float" {
            return Err(child.error(format!(
                "\"{name}\" must be a <float> (a scene version < 2.0 reads it into \"to_uv\")"
            )));
        }
        *value = child.attr("value").unwrap_or_default().to_owned();
        first.get_or_insert_with(|| child.location.clone());
    }
    let Some(location) = first else {
        return Ok(());
    };
    let [(_, u_offset), (_, v_offset), (_, u_scale), (_, v_scale)] = values;
    let op = |tag: &str, x: String, y: String, z: &str| Element {
        tag: tag.into(),
        attrs: vec![("x".into(), x), ("y".into(), y), ("z".into(), z.into())],
        children: Vec::new(),
        location: location.clone(),
    };
    let to_uv = Element {
        tag: "transform".into(),
        attrs: vec![("name".into(), "to_uv".into())],
        // Composed in file order: the translation first, then the scale.
        children: vec![
            op("translate", u_offset, v_offset, "0"),
            op("scale", u_scale, v_scale, "1"),
        ],
        location: location.clone(),
    };
    el.children.retain(|c| {
        !matches!(
            c.attr("name"),
            Some("uoffset" | "voffset" | "uscale" | "vscale")
        )
    });
    el.children.push(to_uv);
    Ok(())
}

fn set_name(el: &mut Element, name: &str) {
    for (key, value) in &mut el.attrs {
        if key == "name" {
            *value = name.to_owned();
        }
    }
}
