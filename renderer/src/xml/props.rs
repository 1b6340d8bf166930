//! A plugin's parameters: the `<float>`, `<rgb>`, `<transform>`… children of a plugin element
//! and its nested plugins, parsed and type-checked, with tracking of which ones were used so
//! that unknown parameters can be reported.

use super::{transform, Builder, Element, SceneError};
use crate::spectrum::{spectrum_list_to_srgb, uniform_spectrum_to_srgb, Rgb, SpectrumKind};
use crate::texture::Texture;
use glam::{Mat4, Vec3};

/// A `<spectrum>` value before conversion (the conversion depends on where it is used).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum SpectrumValue {
    /// One value at all wavelengths.
    Uniform(f64),
    /// `(wavelength nm, value)` pairs, wavelengths strictly increasing.
    Pairs(Vec<(f64, f64)>),
}

impl SpectrumValue {
    /// Linear sRGB as Mitsuba's RGB variants compute it.
    pub fn to_rgb(&self, kind: SpectrumKind) -> Rgb {
        match self {
            SpectrumValue::Uniform(v) => uniform_spectrum_to_srgb(*v, kind),
            SpectrumValue::Pairs(p) => spectrum_list_to_srgb(p, kind),
        }
    }
}

/// A parsed parameter value.
#[derive(Debug, Clone)]
pub(crate) enum Value<'a> {
    Float(f64),
    Integer(i64),
    Boolean(bool),
    Str(&'a str),
    Rgb(Rgb),
    Spectrum(SpectrumValue),
    Vector(Vec3),
    Transform(Mat4),
    /// A nested plugin element or a `<ref>`.
    Object(&'a Element),
}

impl Value<'_> {
    fn type_name(&self) -> &'static str {
        match self {
            Value::Float(_) => "float",
            Value::Integer(_) => "integer",
            Value::Boolean(_) => "boolean",
            Value::Str(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Spectrum(_) => "spectrum",
            Value::Vector(_) => "point/vector",
            Value::Transform(_) => "transform",
            Value::Object(_) => "object",
        }
    }
}

/// One parameter: its name (empty for unnamed nested plugins), value and element.
#[derive(Debug)]
struct Prop<'a> {
    name: &'a str,
    value: Value<'a>,
    element: &'a Element,
    used: bool,
}

/// The parameters of one plugin element.
#[derive(Debug)]
pub(crate) struct Props<'a> {
    /// The plugin element.
    pub owner: &'a Element,
    items: Vec<Prop<'a>>,
}

/// Tags that declare a nested plugin (or a reference to one).
const OBJECT_TAGS: [&str; 13] = [
    "bsdf",
    "medium",
    "phase",
    "volume",
    "texture",
    "emitter",
    "shape",
    "sensor",
    "film",
    "sampler",
    "rfilter",
    "integrator",
    "ref",
];

/// Parses a floating-point number; non-finite values and trailing garbage are errors.
pub(crate) fn parse_float(el: &Element, s: &str) -> Result<f64, SceneError> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(el.error(format!("could not parse floating point value \"{s}\""))),
    }
}

/// Parses a list of numbers separated by commas and/or whitespace.
pub(crate) fn parse_floats(el: &Element, s: &str) -> Result<Vec<f64>, SceneError> {
    s.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| parse_float(el, t))
        .collect()
}

/// Parses a `<spectrum value>`: one number, or `wavelength:value` pairs.
fn parse_spectrum(el: &Element, s: &str) -> Result<SpectrumValue, SceneError> {
    if !s.contains(':') {
        let v = parse_floats(el, s)?;
        return match v.as_slice() {
            [x] => Ok(SpectrumValue::Uniform(*x)),
            _ => Err(el.error(format!(
                "a spectrum needs one value or wavelength:value pairs, got \"{s}\""
            ))),
        };
    }
    let mut pairs = Vec::new();
    for token in s
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
    {
        let Some((w, v)) = token.split_once(':') else {
            return Err(el.error(format!("expected wavelength:value, got \"{token}\"")));
        };
        pairs.push((parse_float(el, w)?, parse_float(el, v)?));
    }
    check_pairs(el, &pairs)?;
    Ok(SpectrumValue::Pairs(pairs))
}

fn check_pairs(el: &Element, pairs: &[(f64, f64)]) -> Result<(), SceneError> {
    if pairs.is_empty() {
        return Err(el.error("empty spectrum"));
    }
    if pairs.windows(2).any(|w| w[1].0 <= w[0].0) {
        return Err(el.error("spectrum wavelengths must be strictly increasing"));
    }
    Ok(())
}

/// Reads a `.spd` file: one `wavelength value` pair per line, `#` comments.
fn read_spd(el: &Element, path: &std::path::Path) -> Result<SpectrumValue, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        el.error(format!(
            "cannot read spectrum file \"{}\": {e}",
            path.display()
        ))
    })?;
    let mut pairs = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = line
            .split_whitespace()
            .filter_map(|t| t.parse().ok())
            .collect();
        match v.as_slice() {
            [w, x] if w.is_finite() && x.is_finite() => pairs.push((*w, *x)),
            _ => {
                return Err(el.error(format!(
                    "{}:{}: expected \"wavelength value\", got \"{line}\"",
                    path.display(),
                    i + 1
                )));
            }
        }
    }
    check_pairs(el, &pairs)?;
    Ok(SpectrumValue::Pairs(pairs))
}

/// A `<spectrum type="…">` plugin, as Mitsuba's RGB variants evaluate it: `uniform` (`value`)
/// is a grey, `srgb` (`color`, in [0, 1] unless `unbounded`) its colour, `d65` (`scale`,
/// optional `color`) the colour times the scale (white by default). The measured spectra
/// (`blackbody`, `regular`, `irregular`) have no RGB form: Mitsuba's RGB variants refuse them too.
pub(crate) fn typed_spectrum<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<Option<Value<'a>>, SceneError> {
    el.check_attributes(&["type", "name", "id"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if ["blackbody", "regular", "irregular"].contains(&kind) {
        return Err(el.error(format!(
            "spectrum \"{kind}\" has no RGB form (Mitsuba's RGB variants refuse it too): give the colour as <rgb> or <spectrum value=\"…\">"
        )));
    }
    if !["uniform", "srgb", "d65"].contains(&kind) {
        b.diag.unknown(el.error(format!(
            "unknown plugin \"{kind}\" (supported spectra: uniform, srgb, d65)"
        )))?;
        return Ok(None);
    }
    let mut p = Props::parse(b, el)?;
    let colour = |p: &mut Props<'a>, name: &str| -> Result<Option<Rgb>, SceneError> {
        let e = p.element_of(name);
        match p.take(name) {
            None => Ok(None),
            Some((Value::Rgb(c), _)) => Ok(Some(c)),
            Some((Value::Float(v), _)) => Ok(Some(Rgb::splat(v as f32))),
            Some((v, _)) => Err(Props::wrong_type(e, name, "rgb", &v)),
        }
    };
    let value = match kind {
        "uniform" => {
            let Some(v) = p.float("value")? else {
                return Err(el.error("missing parameter \"value\""));
            };
            // Bounds of the wavelength range; an RGB renderer has no wavelengths to bound.
            p.ignore(
                b,
                &["wavelength_min", "wavelength_max"],
                "RGB rendering has no wavelengths",
            );
            Rgb::splat(v as f32)
        }
        "srgb" => {
            let Some(c) = colour(&mut p, "color")? else {
                return Err(el.error("missing parameter \"color\""));
            };
            let unbounded = p.bool_or("unbounded", false)?;
            if !unbounded && (c.min_element() < 0.0 || c.max_element() > 1.0) {
                return Err(p.element_of("color").error(format!(
                    "an srgb colour must be in [0, 1], got {c} (set \"unbounded\" for a larger one)"
                )));
            }
            c
        }
        _ => {
            let scale = p.float_or("scale", 1.0)? as f32;
            colour(&mut p, "color")?.unwrap_or(Rgb::ONE) * scale
        }
    };
    p.finish(b)?;
    Ok(Some(Value::Rgb(value)))
}

impl<'a> Props<'a> {
    /// Parses every child of `owner` as a parameter or nested plugin.
    pub fn parse(b: &mut Builder<'a>, owner: &'a Element) -> Result<Self, SceneError> {
        let mut items: Vec<Prop<'a>> = Vec::new();
        for el in &owner.children {
            let Some(value) = Self::parse_value(b, el)? else {
                continue;
            };
            let name = el.attr("name").unwrap_or("");
            if !name.is_empty() {
                if let Some(prev) = items.iter().find(|p| p.name == name) {
                    return Err(el.error(format!(
                        "parameter \"{name}\" given twice (first at {})",
                        prev.element.location
                    )));
                }
            }
            items.push(Prop {
                name,
                value,
                element: el,
                used: false,
            });
        }
        Ok(Self { owner, items })
    }

    fn parse_value(b: &mut Builder<'a>, el: &'a Element) -> Result<Option<Value<'a>>, SceneError> {
        if el.tag == "spectrum" && el.attr("type").is_some() {
            return typed_spectrum(b, el);
        }
        let d = &mut b.diag;
        let tag = el.tag.as_str();
        let value_attr = || el.attr("value").unwrap_or_default();
        let v = match tag {
            "float" => {
                el.check_attributes(&["name", "value"], &["name", "value"], d)?;
                Value::Float(parse_float(el, value_attr())?)
            }
            "integer" => {
                el.check_attributes(&["name", "value"], &["name", "value"], d)?;
                let s = value_attr();
                let i = s
                    .trim()
                    .parse::<i64>()
                    .map_err(|_| el.error(format!("could not parse integer value \"{s}\"")))?;
                Value::Integer(i)
            }
            "boolean" => {
                el.check_attributes(&["name", "value"], &["name", "value"], d)?;
                let s = value_attr();
                match s.trim().to_ascii_lowercase().as_str() {
                    "true" => Value::Boolean(true),
                    "false" => Value::Boolean(false),
                    _ => {
                        return Err(el.error(format!(
                            "could not parse boolean value \"{s}\" (must be \"true\" or \"false\")"
                        )))
                    }
                }
            }
            "string" => {
                el.check_attributes(&["name", "value"], &["name", "value"], d)?;
                Value::Str(el.attr("value").unwrap_or_default())
            }
            "rgb" => {
                el.check_attributes(&["name", "value"], &["name", "value"], d)?;
                let v = parse_floats(el, value_attr())?;
                match v.as_slice() {
                    [x] => Value::Rgb(Rgb::splat(*x as f32)),
                    [r, g, bl] => Value::Rgb(Rgb::new(*r as f32, *g as f32, *bl as f32)),
                    _ => {
                        return Err(
                            el.error(format!("<rgb> needs one or three values, got {}", v.len()))
                        )
                    }
                }
            }
            "spectrum" if el.attr("type").is_none() => {
                el.check_attributes(&["name", "value", "filename"], &["name"], d)?;
                match (el.attr("value"), el.attr("filename")) {
                    (Some(v), None) => Value::Spectrum(parse_spectrum(el, v)?),
                    (None, Some(f)) => {
                        Value::Spectrum(read_spd(el, &el.resolve_path(f, &d.search_paths))?)
                    }
                    _ => {
                        return Err(el
                            .error("<spectrum> needs either \"value\" or \"filename\" (not both)"))
                    }
                }
            }
            "point" | "vector" => {
                el.check_attributes(&["name", "value", "x", "y", "z"], &["name"], d)?;
                let v = match el.attr("value") {
                    Some(s) => {
                        if el.attr("x").is_some()
                            || el.attr("y").is_some()
                            || el.attr("z").is_some()
                        {
                            return Err(el.error("give either \"value\" or x/y/z, not both"));
                        }
                        let v = parse_floats(el, s)?;
                        match v.as_slice() {
                            [x] => Vec3::splat(*x as f32),
                            [x, y, z] => Vec3::new(*x as f32, *y as f32, *z as f32),
                            _ => {
                                return Err(el.error(format!(
                                    "<{tag}> needs one or three values, got {}",
                                    v.len()
                                )))
                            }
                        }
                    }
                    None => {
                        let mut c = [0.0f32; 3];
                        for (i, k) in ["x", "y", "z"].iter().enumerate() {
                            let s = el
                                .attr(k)
                                .ok_or_else(|| el.error(format!("missing attribute \"{k}\"")))?;
                            c[i] = parse_float(el, s)? as f32;
                        }
                        Vec3::from(c)
                    }
                };
                Value::Vector(v)
            }
            "transform" => {
                el.check_attributes(&["name"], &["name"], d)?;
                Value::Transform(transform::parse_transform(el, d)?)
            }
            _ if OBJECT_TAGS.contains(&tag) || tag == "spectrum" => Value::Object(el),
            _ => {
                d.unknown(el.error(format!(
                    "unexpected element <{tag}> inside {}",
                    el_owner_hint(tag)
                )))?;
                return Ok(None);
            }
        };
        Ok(Some(v))
    }

    /// Whether a parameter `name` was given.
    pub fn has(&self, name: &str) -> bool {
        self.items.iter().any(|p| p.name == name)
    }

    /// Takes parameter `name` (marking it used).
    fn take(&mut self, name: &str) -> Option<(Value<'a>, &'a Element)> {
        let p = self.items.iter_mut().find(|p| p.name == name)?;
        p.used = true;
        Some((p.value.clone(), p.element))
    }

    fn wrong_type(el: &Element, name: &str, expected: &str, got: &Value) -> SceneError {
        el.error(format!(
            "parameter \"{name}\" has the wrong type (expected {expected}, got {})",
            got.type_name()
        ))
    }

    /// A float parameter (integers are accepted).
    pub fn float(&mut self, name: &str) -> Result<Option<f64>, SceneError> {
        match self.take(name) {
            None => Ok(None),
            Some((Value::Float(v), _)) => Ok(Some(v)),
            Some((Value::Integer(v), _)) => Ok(Some(v as f64)),
            Some((v, el)) => Err(Self::wrong_type(el, name, "float", &v)),
        }
    }

    /// A float parameter with a default.
    pub fn float_or(&mut self, name: &str, default: f64) -> Result<f64, SceneError> {
        Ok(self.float(name)?.unwrap_or(default))
    }

    /// A float parameter that must be positive (> 0).
    pub fn positive_float_or(&mut self, name: &str, default: f64) -> Result<f64, SceneError> {
        let el = self.element_of(name);
        let v = self.float_or(name, default)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(el.error(format!("parameter \"{name}\" must be positive, got {v}")))
        }
    }

    /// An integer parameter.
    pub fn int(&mut self, name: &str) -> Result<Option<i64>, SceneError> {
        match self.take(name) {
            None => Ok(None),
            Some((Value::Integer(v), _)) => Ok(Some(v)),
            Some((v, el)) => Err(Self::wrong_type(el, name, "integer", &v)),
        }
    }

    /// An integer parameter that must be a `u32` of at least `min`: otherwise an error at its
    /// element, "must be positive" (`min` 1) or "must be >= min", with the value.
    pub fn count(&mut self, name: &str, min: u32) -> Result<Option<u32>, SceneError> {
        let at = self.element_of(name);
        match self.int(name)? {
            None => Ok(None),
            Some(v) if (i64::from(min)..=i64::from(u32::MAX)).contains(&v) => Ok(Some(v as u32)),
            Some(v) => {
                let bound = match min {
                    1 => "positive".to_owned(),
                    _ => format!(">= {min}"),
                };
                Err(at.error(format!("\"{name}\" must be {bound}, got {v}")))
            }
        }
    }

    /// A boolean parameter with a default.
    pub fn bool_or(&mut self, name: &str, default: bool) -> Result<bool, SceneError> {
        match self.take(name) {
            None => Ok(default),
            Some((Value::Boolean(v), _)) => Ok(v),
            Some((v, el)) => Err(Self::wrong_type(el, name, "boolean", &v)),
        }
    }

    /// A string parameter.
    pub fn string(&mut self, name: &str) -> Result<Option<&'a str>, SceneError> {
        match self.take(name) {
            None => Ok(None),
            Some((Value::Str(v), _)) => Ok(Some(v)),
            Some((v, el)) => Err(Self::wrong_type(el, name, "string", &v)),
        }
    }

    /// A point or vector parameter.
    pub fn vector(&mut self, name: &str) -> Result<Option<Vec3>, SceneError> {
        match self.take(name) {
            None => Ok(None),
            Some((Value::Vector(v), _)) => Ok(Some(v)),
            Some((v, el)) => Err(Self::wrong_type(el, name, "point or vector", &v)),
        }
    }

    /// A transform parameter.
    pub fn transform(&mut self, name: &str) -> Result<Option<Mat4>, SceneError> {
        match self.take(name) {
            None => Ok(None),
            Some((Value::Transform(v), _)) => Ok(Some(v)),
            Some((v, el)) => Err(Self::wrong_type(el, name, "transform", &v)),
        }
    }

    /// A float-or-IOR-name parameter (`int_ior`, `ext_ior`): returns the number, or looks the
    /// name up in the table of named dielectrics.
    pub fn ior(&mut self, name: &str, default: &str) -> Result<f64, SceneError> {
        let (value, el) = match self.take(name) {
            None => return Ok(super::ior::dielectric_ior(default).unwrap_or(1.0) as f64),
            Some(x) => x,
        };
        let v = match value {
            Value::Float(v) => v,
            Value::Integer(v) => v as f64,
            Value::Str(s) => match super::ior::dielectric_ior(s) {
                Some(v) => v as f64,
                None => {
                    let names = super::ior::dielectric_names().join(", ");
                    return Err(el.error(format!("unknown IOR name \"{s}\"; valid names: {names}")));
                }
            },
            v => return Err(Self::wrong_type(el, name, "float or IOR name", &v)),
        };
        if v > 0.0 {
            Ok(v)
        } else {
            Err(el.error(format!("parameter \"{name}\" must be positive, got {v}")))
        }
    }

    /// A colour-valued parameter as a texture: `<float>`/`<integer>`, `<rgb>`, `<spectrum>`
    /// (converted for use `kind`), a nested `<texture>` or a `<ref>` to one.
    pub fn texture(
        &mut self,
        b: &mut Builder<'a>,
        name: &str,
        kind: SpectrumKind,
    ) -> Result<Option<Texture>, SceneError> {
        let Some((value, el)) = self.take(name) else {
            return Ok(None);
        };
        let tex = match value {
            // Mitsuba: a plain number stays grey, also for emitters.
            Value::Float(v) => Texture::Constant(Rgb::splat(v as f32)),
            Value::Integer(v) => Texture::Constant(Rgb::splat(v as f32)),
            Value::Rgb(c) => Texture::Constant(c),
            Value::Spectrum(s) => Texture::Constant(s.to_rgb(kind)),
            Value::Object(o) if o.tag == "texture" || o.tag == "ref" => b.texture_value(o)?,
            v => {
                return Err(Self::wrong_type(
                    el,
                    name,
                    "texture, rgb, spectrum or float",
                    &v,
                ))
            }
        };
        if let Texture::Constant(c) = &tex {
            if !c.is_finite() {
                return Err(el.error(format!("parameter \"{name}\" is not finite")));
            }
        }
        Ok(Some(tex))
    }

    /// A colour-valued parameter with a grey default.
    pub fn texture_or(
        &mut self,
        b: &mut Builder<'a>,
        name: &str,
        kind: SpectrumKind,
        default: f32,
    ) -> Result<Texture, SceneError> {
        Ok(self
            .texture(b, name, kind)?
            .unwrap_or(Texture::Constant(Rgb::splat(default))))
    }

    /// A colour parameter that must be constant (e.g. emitted radiance, complex IOR).
    pub fn constant_color(
        &mut self,
        b: &mut Builder<'a>,
        name: &str,
        kind: SpectrumKind,
    ) -> Result<Option<Rgb>, SceneError> {
        let el = self.element_of(name);
        match self.texture(b, name, kind)? {
            None => Ok(None),
            Some(Texture::Constant(c)) => Ok(Some(c)),
            Some(_) => Err(el.error(format!(
                "parameter \"{name}\" must be a constant colour, not a texture"
            ))),
        }
    }

    /// The nested plugin (or `<ref>`) given as parameter `name`, taken; `None` (and nothing
    /// taken) when the parameter is absent or a plain value.
    pub fn object(&mut self, name: &str) -> Option<&'a Element> {
        let p = self.items.iter_mut().find(|p| p.name == name)?;
        match p.value {
            Value::Object(o) => {
                p.used = true;
                Some(o)
            }
            _ => None,
        }
    }

    /// The element of parameter `name`, or the owner if there is none (for error messages).
    pub fn element_of(&self, name: &str) -> &'a Element {
        self.items
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.element)
            .unwrap_or(self.owner)
    }

    /// Takes every nested plugin (or `<ref>`) whose tag is one of `tags`, named or not, in order
    /// — except those already taken as named parameters (e.g. a texture given by `<ref>`).
    pub fn objects(&mut self, tags: &[&str]) -> Vec<&'a Element> {
        let mut out = Vec::new();
        for p in &mut self.items {
            if let Value::Object(o) = p.value {
                if !p.used && tags.contains(&o.tag.as_str()) {
                    p.used = true;
                    out.push(o);
                }
            }
        }
        out
    }

    /// Marks `names` as known but unused by this renderer: each one given yields a warning.
    pub fn ignore(&mut self, b: &mut Builder<'a>, names: &[&str], why: &str) {
        for name in names {
            if let Some((_, el)) = self.take(name) {
                b.diag
                    .warn(el, format!("parameter \"{name}\" ignored: {why}"));
            }
        }
    }

    /// Reports every parameter that was not used: unknown for this plugin.
    pub fn finish(self, b: &mut Builder<'a>) -> Result<(), SceneError> {
        let plugin = self.owner.describe();
        for p in self.items.iter().filter(|p| !p.used) {
            let what = if p.name.is_empty() {
                format!("unexpected nested {} in {plugin}", p.element.describe())
            } else {
                format!("unknown parameter \"{}\" of {plugin}", p.name)
            };
            b.diag.unknown(p.element.error(what))?;
        }
        Ok(())
    }
}

/// Helps the "unexpected element" message.
fn el_owner_hint(_tag: &str) -> &'static str {
    "a plugin (expected a parameter like <float>, <rgb>, <string>, <transform> or a nested plugin)"
}
