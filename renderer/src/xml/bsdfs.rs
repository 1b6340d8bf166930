//! `<bsdf>` plugins → [`Bsdf`] values, with Mitsuba 3's parameter names and defaults.

use super::props::Props;
use super::{ior, Builder, Element, SceneError};
use crate::bsdf::{
    Blend, Bsdf, BumpMap, Conductor, ConductorIor, Dielectric, Diffuse, Mask, MicrofacetKind,
    NormalMap, Plastic, Principled, PrincipledIor, PrincipledParams, PrincipledThin,
    PrincipledThinParams, RoughConductor, RoughDielectric, RoughPlastic, Roughness, ThinDielectric,
};
use crate::spectrum::{Rgb, SpectrumKind};
use crate::texture::Texture;

/// The BSDF plugins this importer knows.
const BSDF_PLUGINS: [&str; 16] = [
    "diffuse",
    "conductor",
    "roughconductor",
    "dielectric",
    "thindielectric",
    "roughdielectric",
    "plastic",
    "roughplastic",
    "principled",
    "principledthin",
    "twosided",
    "normalmap",
    "bumpmap",
    "blendbsdf",
    "mask",
    "null",
];

/// Builds the BSDF declared by a `<bsdf>` element.
pub(super) fn build_bsdf<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<Bsdf, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if !BSDF_PLUGINS.contains(&kind) {
        let err = el.error(format!(
            "unknown plugin \"{kind}\" (supported BSDFs: {})",
            BSDF_PLUGINS.join(", ")
        ));
        b.diag.unknown(err)?;
        // Lenient: stand in Mitsuba's default material.
        return Ok(Bsdf::Diffuse(Diffuse {
            reflectance: Texture::Constant(Rgb::splat(0.5)),
        }));
    }
    let mut p = Props::parse(b, el)?;
    let refl = SpectrumKind::Reflectance;
    let bsdf = match kind {
        "diffuse" => Bsdf::Diffuse(Diffuse {
            reflectance: p.texture_or(b, "reflectance", refl, 0.5)?,
        }),
        "conductor" => Bsdf::Conductor(Conductor {
            ior: conductor_ior(b, &mut p)?,
            specular_reflectance: p.texture_or(b, "specular_reflectance", refl, 1.0)?,
        }),
        "roughconductor" => {
            let (roughness, alpha_texture) = roughness(b, &mut p, true)?;
            Bsdf::RoughConductor(RoughConductor {
                roughness,
                alpha_texture,
                ior: conductor_ior(b, &mut p)?,
                specular_reflectance: p.texture_or(b, "specular_reflectance", refl, 1.0)?,
            })
        }
        "dielectric" | "thindielectric" | "roughdielectric" => {
            let (roughness, alpha_texture) = if kind == "roughdielectric" {
                let (r, t) = roughness(b, &mut p, true)?;
                (Some(r), t)
            } else {
                (None, None)
            };
            let eta = relative_ior(&mut p, "bk7")?;
            let specular_reflectance = p.texture_or(b, "specular_reflectance", refl, 1.0)?;
            let specular_transmittance = p.texture_or(b, "specular_transmittance", refl, 1.0)?;
            match (kind, roughness) {
                ("dielectric", _) => Bsdf::Dielectric(Dielectric {
                    eta,
                    specular_reflectance,
                    specular_transmittance,
                }),
                ("thindielectric", _) => Bsdf::ThinDielectric(ThinDielectric {
                    eta,
                    specular_reflectance,
                    specular_transmittance,
                }),
                (_, Some(roughness)) => Bsdf::RoughDielectric(RoughDielectric {
                    roughness,
                    alpha_texture,
                    eta,
                    specular_reflectance,
                    specular_transmittance,
                }),
                _ => unreachable_plugin(el)?,
            }
        }
        "plastic" => Bsdf::Plastic(Plastic {
            eta: relative_ior(&mut p, "polypropylene")?,
            diffuse_reflectance: texture_read_as(
                b,
                &mut p,
                "diffuse_reflectance",
                0.5,
                Read::Mean,
            )?,
            specular_reflectance: texture_read_as(
                b,
                &mut p,
                "specular_reflectance",
                1.0,
                Read::Mean,
            )?,
            nonlinear: p.bool_or("nonlinear", false)?,
        }),
        "roughplastic" => Bsdf::RoughPlastic(RoughPlastic::new(
            {
                let alpha_el = p.element_of("alpha");
                match roughness(b, &mut p, false)? {
                    (r, None) => r,
                    (_, Some(_)) => {
                        return Err(alpha_el.error(
                            "roughplastic needs a constant \"alpha\" (its coating tables are \
                             computed for one roughness)",
                        ))
                    }
                }
            },
            relative_ior(&mut p, "polypropylene")?,
            texture_read_as(b, &mut p, "diffuse_reflectance", 0.5, Read::Mean)?,
            texture_read_as(b, &mut p, "specular_reflectance", 1.0, Read::Mean)?,
            p.bool_or("nonlinear", false)?,
        )),
        "principled" => Bsdf::Principled(principled(b, &mut p)?),
        "principledthin" => Bsdf::PrincipledThin(principled_thin(b, &mut p)?),
        "twosided" => {
            let nested = p.objects(&["bsdf", "ref"]);
            let allow_transmission = p.bool_or("allow_transmission", false)?;
            let mut sides = Vec::with_capacity(2);
            for n in &nested {
                let side = b.bsdf_value(n)?;
                if matches!(side, Bsdf::TwoSided { .. }) {
                    return Err(n.error("a twosided BSDF cannot contain another twosided BSDF"));
                }
                if !allow_transmission && has_transmission(&side) {
                    return Err(n.error(
                        "a twosided BSDF's models must not transmit light (as in Mitsuba); set \"allow_transmission\" to true to nest this one",
                    ));
                }
                sides.push(side);
            }
            match sides.len() {
                1 => {
                    let front = sides.remove(0);
                    Bsdf::TwoSided {
                        back: Box::new(front.clone()),
                        front: Box::new(front),
                    }
                }
                2 => {
                    let back = sides.pop().map(Box::new);
                    let front = sides.pop().map(Box::new);
                    match (front, back) {
                        (Some(front), Some(back)) => Bsdf::TwoSided { front, back },
                        _ => unreachable_plugin(el)?,
                    }
                }
                n => {
                    return Err(el.error(format!("twosided needs one or two nested BSDFs, got {n}")))
                }
            }
        }
        "normalmap" => {
            let normalmap_el = p.element_of("normalmap");
            let Some(normalmap) = p.texture(b, "normalmap", SpectrumKind::Unbounded)? else {
                return Err(el.error("missing parameter \"normalmap\" (a texture)"));
            };
            check_read(normalmap_el, "normalmap", &normalmap, Read::ThreeChannels)?;
            let [inner] = nested_bsdfs(b, &mut p, el, "one")?;
            Bsdf::NormalMap(NormalMap {
                normalmap,
                nested: Box::new(inner),
                flip_invalid_normals: p.bool_or("flip_invalid_normals", true)?,
                use_shadowing_function: p.bool_or("use_shadowing_function", true)?,
            })
        }
        "bumpmap" => {
            // Mitsuba takes the one nested texture and the one nested BSDF, whatever their
            // names; a `<ref>` counts as what it refers to.
            let (mut textures, mut nested) = (Vec::new(), Vec::new());
            for o in p.objects(&["bsdf", "texture", "ref"]) {
                if b.deref(o)?.tag == "texture" {
                    textures.push(o);
                } else {
                    nested.push(o);
                }
            }
            let [texture] = textures[..] else {
                return Err(el.error(format!(
                    "bumpmap needs exactly one nested texture (the height field), got {}",
                    textures.len()
                )));
            };
            let [inner] = nested[..] else {
                return Err(el.error(format!(
                    "bumpmap needs exactly one nested BSDF, got {}",
                    nested.len()
                )));
            };
            let height = b.texture_value(texture)?;
            if !matches!(height, Texture::Bitmap { .. }) {
                return Err(texture.error(
                    "bumpmap needs a bitmap height field (Mitsuba computes texture gradients \
                     for bitmaps only)",
                ));
            }
            Bsdf::BumpMap(BumpMap {
                height,
                scale: p.float_or("scale", 1.0)? as f32,
                nested: Box::new(b.bsdf_value(inner)?),
                flip_invalid_normals: p.bool_or("flip_invalid_normals", true)?,
                use_shadowing_function: p.bool_or("use_shadowing_function", true)?,
            })
        }
        "blendbsdf" => {
            let weight = texture_read_as(b, &mut p, "weight", 0.5, Read::OneChannel)?;
            Bsdf::Blend(Blend {
                weight,
                nested: Box::new(nested_bsdfs(b, &mut p, el, "two")?),
            })
        }
        "mask" => {
            let opacity = texture_read_as(b, &mut p, "opacity", 0.5, Read::OneChannel)?;
            let [inner] = nested_bsdfs(b, &mut p, el, "one")?;
            Bsdf::Mask(Mask {
                opacity,
                nested: Box::new(inner),
            })
        }
        // Mitsuba's `null` (no parameters): light passes straight through, as through a mask
        // of opacity 0 — which is what Mitsuba's `path` renders for it too (shadow rays are
        // blocked by the shape, paths continue through it).
        "null" => Bsdf::Mask(Mask {
            opacity: Texture::Constant(Rgb::ZERO),
            nested: Box::new(Bsdf::Diffuse(Diffuse {
                reflectance: Texture::Constant(Rgb::ZERO),
            })),
        }),
        _ => unreachable_plugin(el)?,
    };
    p.finish(b)?;
    Ok(bsdf)
}

/// Whether a model has a transmission component in Mitsuba's sense (its `BSDFFlags::Transmission`,
/// the pass-through of a mask or `null` included), which `twosided` refuses unless
/// `allow_transmission`.
fn has_transmission(bsdf: &Bsdf) -> bool {
    match bsdf {
        Bsdf::Diffuse(_)
        | Bsdf::Conductor(_)
        | Bsdf::RoughConductor(_)
        | Bsdf::Plastic(_)
        | Bsdf::RoughPlastic(_) => false,
        Bsdf::Dielectric(_)
        | Bsdf::ThinDielectric(_)
        | Bsdf::RoughDielectric(_)
        | Bsdf::Mask(_) => true,
        // Mitsuba flags transmission whenever `spec_trans` is given.
        Bsdf::Principled(p) => p.transmits(),
        // Mitsuba lists its diffuse transmission lobe whatever `diff_trans` is.
        Bsdf::PrincipledThin(_) => true,
        Bsdf::TwoSided { front, back } => has_transmission(front) || has_transmission(back),
        Bsdf::NormalMap(b) => has_transmission(&b.nested),
        Bsdf::BumpMap(b) => has_transmission(&b.nested),
        Bsdf::Blend(b) => b.nested.iter().any(has_transmission),
    }
}

/// Exactly `N` nested `<bsdf>`s (or `<ref>`s to them), in file order; `count` spells `N` for
/// the error.
fn nested_bsdfs<'a, const N: usize>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    el: &'a Element,
    count: &str,
) -> Result<[Bsdf; N], SceneError> {
    let nested = p.objects(&["bsdf", "ref"]);
    if nested.len() != N {
        let kind = el.attr("type").unwrap_or_default();
        return Err(el.error(format!(
            "{kind} needs exactly {count} nested BSDF{}, got {}",
            if N == 1 { "" } else { "s" },
            nested.len()
        )));
    }
    let mut out = Vec::with_capacity(N);
    for n in nested {
        out.push(b.bsdf_value(n)?);
    }
    out.try_into()
        .map_err(|_| el.error("internal error: nested BSDF count"))
}

/// Internal consistency guard (never reached: the plugin list was checked above).
fn unreachable_plugin(el: &Element) -> Result<Bsdf, SceneError> {
    Err(el.error("internal error: unhandled BSDF plugin"))
}

/// `int_ior` / `ext_ior` (numbers or names) → relative IOR.
fn relative_ior(p: &mut Props, default_int: &str) -> Result<f32, SceneError> {
    let int_ior = p.ior("int_ior", default_int)?;
    let ext_ior = p.ior("ext_ior", "air")?;
    Ok((int_ior / ext_ior) as f32)
}

/// `distribution`, `alpha` or `alpha_u`/`alpha_v` (Mitsuba defaults: beckmann, 0.1), and the
/// texture when `alpha` is one (isotropic only; its mean fills the constant roughness).
fn roughness<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    anisotropic: bool,
) -> Result<(Roughness, Option<Texture>), SceneError> {
    let dist_el = p.element_of("distribution");
    let kind = match p.string("distribution")?.unwrap_or("beckmann") {
        "beckmann" => MicrofacetKind::Beckmann,
        "ggx" => MicrofacetKind::Ggx,
        other => {
            return Err(dist_el.error(format!(
                "unknown microfacet distribution \"{other}\" (use \"beckmann\" or \"ggx\")"
            )))
        }
    };
    let has_uv = p.has("alpha_u") || p.has("alpha_v");
    let mut textured = None;
    let (alpha_u, alpha_v) = if anisotropic && has_uv {
        if p.has("alpha") {
            return Err(p
                .element_of("alpha")
                .error("give either \"alpha\" or \"alpha_u\"/\"alpha_v\", not both"));
        }
        let (Some(u), Some(v)) = (scalar(p, "alpha_u")?, scalar(p, "alpha_v")?) else {
            return Err(p
                .owner
                .error("\"alpha_u\" and \"alpha_v\" must be given together"));
        };
        (u, v)
    } else {
        match p.texture(b, "alpha", SpectrumKind::Unbounded)? {
            None => (0.1, 0.1),
            Some(t @ Texture::Constant(_)) => {
                let a = t.mean_1() as f64;
                (a, a)
            }
            Some(t) => {
                let alpha_el = p.element_of("alpha");
                check_read(alpha_el, "alpha", &t, Read::OneChannel)?;
                if !t.is_finite_non_negative() {
                    return Err(alpha_el
                        .error("roughness texture \"alpha\" has negative or non-finite values"));
                }
                let a = t.mean_1() as f64;
                textured = Some(t);
                (a, a)
            }
        }
    };
    for (name, a) in [("alpha", alpha_u), ("alpha_v", alpha_v)] {
        if !(0.0..=10.0).contains(&a) {
            return Err(p
                .owner
                .error(format!("roughness \"{name}\" = {a} is out of range")));
        }
    }
    let sample_visible_el = p.element_of("sample_visible");
    if !p.bool_or("sample_visible", true)? {
        b.diag.warn(sample_visible_el, "sample_visible=false ignored: visible normals are always sampled (same image, less noise)");
    }
    Ok((
        Roughness {
            kind,
            alpha_u: alpha_u as f32,
            alpha_v: alpha_v as f32,
        },
        textured,
    ))
}

/// An anisotropic roughness value `alpha_u` / `alpha_v`: a float (only the isotropic `alpha`
/// may be a texture).
fn scalar(p: &mut Props, name: &str) -> Result<Option<f64>, SceneError> {
    p.float(name)
}

/// `material` or `eta`/`k` of a conductor; `None` is Mitsuba's `material="none"` (a perfect
/// mirror, the default).
fn conductor_ior<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
) -> Result<Option<ConductorIor>, SceneError> {
    let material_el = p.element_of("material");
    let material = p.string("material")?.unwrap_or("none");
    let given = p.has("eta") || p.has("k");
    if material != "none" {
        if given {
            return Err(material_el.error("give either \"material\" or \"eta\"/\"k\", not both"));
        }
        return match ior::conductor_ior(material) {
            Some(ior) => Ok(Some(ior)),
            None => Err(material_el.error(format!(
                "unknown conductor material \"{material}\"; valid presets: none, {}",
                ior::conductor_names().join(", ")
            ))),
        };
    }
    if !given {
        return Ok(None);
    }
    // Mitsuba: eta defaults to 0 and k to 1 when only one is given.
    let eta = p
        .constant_color(b, "eta", SpectrumKind::Unbounded)?
        .unwrap_or(Rgb::ZERO);
    let k = p
        .constant_color(b, "k", SpectrumKind::Unbounded)?
        .unwrap_or(Rgb::ONE);
    Ok(Some(ConductorIor { eta, k }))
}

/// `principled`: every parameter of Mitsuba 3's plugin. The artist parameters must lie in
/// [0, 1] (Mitsuba's documentation: "all of the parameters except sampling rates and eta should
/// take values between 0.0 and 1.0"; outside it the lobe weights turn negative); `base_color`
/// may exceed 1 but not be negative, `eta` must be positive, the sampling rates non-negative.
fn principled<'a>(b: &mut Builder<'a>, p: &mut Props<'a>) -> Result<Principled, SceneError> {
    let base_el = p.element_of("base_color");
    let base_color = p.texture_or(b, "base_color", SpectrumKind::Reflectance, 0.5)?;
    if !base_color.is_finite_non_negative() {
        return Err(base_el.error("\"base_color\" has negative or non-finite values"));
    }
    let roughness = principled_scalar(b, p, "roughness")?.unwrap_or(grey(0.5));
    let clearcoat_gloss = principled_scalar(b, p, "clearcoat_gloss")?.unwrap_or(grey(0.0));
    let ior = match (p.has("eta"), p.has("specular")) {
        (true, true) => {
            return Err(p
                .element_of("specular")
                .error("give either \"eta\" or \"specular\", not both"))
        }
        (true, false) => {
            let eta_el = p.element_of("eta");
            let eta = p.float("eta")?.unwrap_or(1.5);
            if !(eta > 0.0 && eta.is_finite()) {
                return Err(eta_el.error(format!("\"eta\" must be positive, got {eta}")));
            }
            PrincipledIor::Eta(eta as f32)
        }
        (false, _) => {
            let specular_el = p.element_of("specular");
            let specular = p.float("specular")?.unwrap_or(0.5);
            if !(0.0..=1.0).contains(&specular) {
                return Err(
                    specular_el.error(format!("\"specular\" = {specular} is outside [0, 1]"))
                );
            }
            PrincipledIor::Specular(specular as f32)
        }
    };
    let diffuse_reflectance_sampling_rate = sampling_rate(p, "diffuse_reflectance_sampling_rate")?;
    let main_specular_sampling_rate = sampling_rate(p, "main_specular_sampling_rate")?;
    let clearcoat_sampling_rate = sampling_rate(p, "clearcoat_sampling_rate")?;
    Ok(Principled::new(PrincipledParams {
        base_color,
        roughness,
        anisotropic: principled_lobe(b, p, "anisotropic")?,
        metallic: principled_lobe(b, p, "metallic")?,
        spec_trans: principled_lobe(b, p, "spec_trans")?,
        ior,
        spec_tint: principled_lobe(b, p, "spec_tint")?,
        sheen: principled_lobe(b, p, "sheen")?,
        sheen_tint: principled_lobe(b, p, "sheen_tint")?,
        flatness: principled_lobe(b, p, "flatness")?,
        clearcoat: principled_lobe(b, p, "clearcoat")?,
        clearcoat_gloss,
        diffuse_reflectance_sampling_rate,
        main_specular_sampling_rate,
        clearcoat_sampling_rate,
    }))
}

fn grey(v: f32) -> Texture {
    Texture::Constant(Rgb::splat(v))
}

/// A scalar principled parameter (float or texture, read by luminance), checked to lie in
/// [0, 1] everywhere.
fn principled_scalar<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    name: &str,
) -> Result<Option<Texture>, SceneError> {
    principled_scalar_up_to(b, p, name, 1.0)
}

/// [`principled_scalar`] for a parameter whose values lie in [0, `max`].
fn principled_scalar_up_to<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    name: &str,
    max: f32,
) -> Result<Option<Texture>, SceneError> {
    let el = p.element_of(name);
    let Some(t) = p.texture(b, name, SpectrumKind::Unbounded)? else {
        return Ok(None);
    };
    check_read(el, name, &t, Read::OneChannel)?;
    let (lo, hi) = t.scalar_range();
    if !(lo >= 0.0 && hi <= max) {
        return Err(el.error(format!(
            "\"{name}\" must lie in [0, {max}], got values in [{lo}, {hi}]"
        )));
    }
    Ok(Some(t))
}

/// A principled parameter that switches a lobe on: `None` when absent or given as the float 0,
/// as Mitsuba's `get_flag` (a zero texture or colour keeps the lobe on).
fn principled_lobe<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    name: &str,
) -> Result<Option<Texture>, SceneError> {
    principled_lobe_up_to(b, p, name, 1.0)
}

/// [`principled_lobe`] for a parameter whose values lie in [0, `max`].
fn principled_lobe_up_to<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    name: &str,
    max: f32,
) -> Result<Option<Texture>, SceneError> {
    let is_float = p.has(name) && p.element_of(name).tag == "float";
    Ok(match principled_scalar_up_to(b, p, name, max)? {
        Some(Texture::Constant(c)) if is_float && c == Rgb::ZERO => None,
        t => t,
    })
}

/// A principled model's sampling rate `name` (default 1, non-negative).
fn sampling_rate(p: &mut Props<'_>, name: &str) -> Result<f32, SceneError> {
    let el = p.element_of(name);
    let v = p.float_or(name, 1.0)?;
    if v >= 0.0 && v.is_finite() {
        Ok(v as f32)
    } else {
        Err(el.error(format!("\"{name}\" must be non-negative, got {v}")))
    }
}

/// Reads a `principledthin` (parameters and their ranges: `bsdf/principledthin.rs`).
fn principled_thin<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
) -> Result<PrincipledThin, SceneError> {
    let base_el = p.element_of("base_color");
    let base_color = p.texture_or(b, "base_color", SpectrumKind::Reflectance, 0.5)?;
    if !base_color.is_finite_non_negative() {
        return Err(base_el.error("\"base_color\" has negative or non-finite values"));
    }
    let roughness = principled_scalar(b, p, "roughness")?.unwrap_or(grey(0.5));
    let eta_el = p.element_of("eta");
    let eta = match p.texture(b, "eta", SpectrumKind::Unbounded)? {
        Some(t) => {
            check_read(eta_el, "eta", &t, Read::OneChannel)?;
            let (lo, hi) = t.scalar_range();
            if !(lo > 0.0 && hi.is_finite()) {
                return Err(eta_el.error(format!(
                    "\"eta\" must be positive and finite, got values in [{lo}, {hi}]"
                )));
            }
            t
        }
        None => grey(1.5),
    };
    Ok(PrincipledThin::new(PrincipledThinParams {
        base_color,
        roughness,
        anisotropic: principled_lobe(b, p, "anisotropic")?,
        spec_trans: principled_lobe(b, p, "spec_trans")?,
        eta,
        spec_tint: principled_lobe(b, p, "spec_tint")?,
        sheen: principled_lobe(b, p, "sheen")?,
        sheen_tint: principled_lobe(b, p, "sheen_tint")?,
        flatness: principled_lobe(b, p, "flatness")?,
        diff_trans: principled_lobe_up_to(b, p, "diff_trans", 2.0)?,
        diffuse_reflectance_sampling_rate: sampling_rate(p, "diffuse_reflectance_sampling_rate")?,
        specular_reflectance_sampling_rate: sampling_rate(p, "specular_reflectance_sampling_rate")?,
        specular_transmittance_sampling_rate: sampling_rate(
            p,
            "specular_transmittance_sampling_rate",
        )?,
        diffuse_transmittance_sampling_rate: sampling_rate(
            p,
            "diffuse_transmittance_sampling_rate",
        )?,
    }))
}

/// How a BSDF reads a texture parameter (Mitsuba's `eval_1`, `eval_3` or `mean`), which decides
/// whether a `mesh_attribute` texture fits it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Read {
    /// As one number (`eval_1`): a 1-channel attribute only.
    OneChannel,
    /// As a colour through `eval_3` (normal maps): a 3-channel attribute only.
    ThreeChannels,
    /// Its mean is taken on load (plastics' sampling weights): no attribute at all, since
    /// Mitsuba 3.9.1's `mesh_attribute` has no mean.
    Mean,
}

/// Refuses a `mesh_attribute` texture `t` in parameter `name` where Mitsuba 3.9.1 cannot read
/// it (scalar variants raise an error; JIT variants give zero or fail on load).
fn check_read(el: &Element, name: &str, t: &Texture, read: Read) -> Result<(), SceneError> {
    let Texture::MeshAttribute { values, .. } = t else {
        return Ok(());
    };
    let (attr, ch) = (&values.name, values.channels);
    let problem = match read {
        Read::OneChannel if ch != 1 => format!(
            "is read as one number (Mitsuba's eval_1), but mesh attribute \"{attr}\" has {ch} channels"
        ),
        Read::ThreeChannels if ch != 3 => format!(
            "is read as a 3-channel colour (Mitsuba's eval_3), but mesh attribute \"{attr}\" has {ch} channel"
        ),
        Read::Mean => format!(
            "cannot be a mesh_attribute texture (\"{attr}\"): the model takes the texture's mean on \
             load, which Mitsuba 3.9.1 does not implement for mesh_attribute"
        ),
        _ => return Ok(()),
    };
    Err(el.error(format!("\"{name}\" {problem}")))
}

/// A colour or number parameter with a grey default, checked by [`check_read`].
fn texture_read_as<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
    name: &str,
    default: f32,
    read: Read,
) -> Result<Texture, SceneError> {
    let el = p.element_of(name);
    let kind = match read {
        Read::Mean => SpectrumKind::Reflectance,
        _ => SpectrumKind::Unbounded,
    };
    let t = p.texture_or(b, name, kind, default)?;
    check_read(el, name, &t, read)?;
    Ok(t)
}
