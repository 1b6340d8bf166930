//! `<sensor>` (`perspective`, `thinlens`, `orthographic`) with its `<film>` (`hdrfilm`), `<rfilter>` and
//! `<sampler>` (declared inside it, or at the top level and named by a `<ref>`), and the
//! `<integrator>`.

use super::props::Props;
use super::{Builder, Element, SceneError};
use crate::description::{CameraDesc, FilmCrop, FovAxis, IntegratorDesc, Projection};
use crate::filter::FilterDesc;
use glam::Mat4;

/// Mitsuba's default film size.
const DEFAULT_WIDTH: u32 = 768;
const DEFAULT_HEIGHT: u32 = 576;

/// Largest accepted film side (guards against absurd allocations).
const MAX_FILM_SIDE: i64 = 1 << 16;

/// The camera used when a scene has no `<sensor>`.
pub(super) fn default_camera() -> CameraDesc {
    CameraDesc {
        to_world: Mat4::IDENTITY,
        projection: Projection::Perspective,
        fov: 45.0,
        fov_axis: FovAxis::X,
        near_clip: 0.01,
        far_clip: 10_000.0,
        aperture_radius: 0.0,
        focus_distance: 10_000.0,
        width: DEFAULT_WIDTH,
        height: DEFAULT_HEIGHT,
        filter: FilterDesc::MITSUBA_DEFAULT,
        sample_border: false,
        crop: None,
        principal_point: glam::Vec2::ZERO,
    }
}

/// What the sensor takes from its `<film>`.
struct Film {
    /// `width`.
    width: u32,
    /// `height`.
    height: u32,
    /// The `<rfilter>` (Mitsuba's Gaussian when there is none).
    filter: FilterDesc,
    /// `sample_border`.
    sample_border: bool,
    /// `crop_offset_x/y`, `crop_width/height` (`None`: the whole film).
    crop: Option<FilmCrop>,
}

/// Builds the camera of a `<sensor>` element (film and sampler included).
pub(super) fn build_sensor<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<CameraDesc, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if !["perspective", "thinlens", "orthographic"].contains(&kind) {
        return Err(el.error(format!(
            "unknown plugin \"{kind}\" (supported sensors: perspective, thinlens, orthographic)"
        )));
    }
    let orthographic = kind == "orthographic";
    let mut p = Props::parse(b, el)?;

    let mut film = Film {
        width: DEFAULT_WIDTH,
        height: DEFAULT_HEIGHT,
        filter: FilterDesc::MITSUBA_DEFAULT,
        sample_border: false,
        crop: None,
    };
    // Declared here, or elsewhere with an id and named by a `<ref>`.
    let mut medium = None;
    for obj in p.objects(&["film", "sampler", "ref", "medium"]) {
        let target = b.deref(obj)?;
        match target.tag.as_str() {
            "film" => film = build_film(b, target)?,
            "sampler" => b.sample_count = Some(build_sampler(b, target)?),
            // The medium the camera sits in (Mitsuba: any name).
            "medium" => {
                if medium.is_some() {
                    return Err(obj.error("a sensor can have only one medium"));
                }
                medium = Some(b.medium_index(obj)?);
            }
            _ => {
                return Err(obj.error(format!(
                    "a sensor refers to a <film>, a <sampler> or a <medium>, not {}",
                    target.describe()
                )))
            }
        }
    }
    // Only the first sensor is used (see `build_scene`).
    if b.camera.is_none() {
        b.camera_medium = medium;
    }

    let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
    // An orthographic view has no field of view: its to_world's scale sizes it.
    let (fov, fov_axis) = if orthographic {
        (45.0, FovAxis::X)
    } else {
        parse_fov(&mut p)?
    };
    let near_clip = p.float_or("near_clip", 0.01)?;
    let far_clip = p.float_or("far_clip", 10_000.0)?;
    if near_clip <= 0.0 {
        return Err(p
            .element_of("near_clip")
            .error("\"near_clip\" must be greater than zero"));
    }
    if near_clip >= far_clip {
        return Err(p
            .element_of("near_clip")
            .error("\"near_clip\" must be smaller than \"far_clip\""));
    }
    let (aperture_radius, focus_distance) = if kind == "thinlens" {
        let Some(r) = p.float("aperture_radius")? else {
            return Err(el.error("missing parameter \"aperture_radius\""));
        };
        if r < 0.0 {
            return Err(p
                .element_of("aperture_radius")
                .error("\"aperture_radius\" must not be negative"));
        }
        let focus = p.positive_float_or("focus_distance", far_clip)?;
        (r, focus)
    } else {
        (0.0, p.float_or("focus_distance", far_clip)?)
    };
    // A camera frame must be rigid: Mitsuba rejects scale factors (a mirror is allowed).
    let m3 = glam::Mat3::from_mat4(to_world);
    let scaled = [m3.x_axis, m3.y_axis, m3.z_axis]
        .iter()
        .any(|c| (c.length() - 1.0).abs() > 1e-3);
    // An orthographic camera is sized by the x/y scale of its to_world (Mitsuba's convention).
    if orthographic {
        if m3.determinant() == 0.0 || !m3.is_finite() {
            return Err(p
                .element_of("to_world")
                .error("an orthographic camera's to_world must not be singular"));
        }
    } else if scaled {
        return Err(p
            .element_of("to_world")
            .error("scale factors in the camera's to_world are not allowed"));
    }
    // Mitsuba's `perspective` only: the principal point's offset from the film centre, in
    // fractions of the film size.
    let principal_point = if kind == "perspective" {
        glam::Vec2::new(
            p.float_or("principal_point_offset_x", 0.0)? as f32,
            p.float_or("principal_point_offset_y", 0.0)? as f32,
        )
    } else {
        glam::Vec2::ZERO
    };
    p.ignore(b, &["shutter_open", "shutter_close"], "no motion blur");
    p.finish(b)?;
    Ok(CameraDesc {
        to_world,
        projection: if orthographic {
            Projection::Orthographic
        } else {
            Projection::Perspective
        },
        fov: fov as f32,
        fov_axis,
        near_clip: near_clip as f32,
        far_clip: far_clip as f32,
        aperture_radius: aperture_radius as f32,
        focus_distance: focus_distance as f32,
        width: film.width,
        height: film.height,
        filter: film.filter,
        sample_border: film.sample_border,
        crop: film.crop,
        principal_point,
    })
}

/// `fov` + `fov_axis`, or a 35 mm-equivalent `focal_length` (default "50mm") as Mitsuba.
pub(super) fn parse_fov(p: &mut Props) -> Result<(f64, FovAxis), SceneError> {
    if p.has("fov") && p.has("focal_length") {
        return Err(p
            .element_of("focal_length")
            .error("give either \"fov\" or \"focal_length\", not both"));
    }
    let (fov, axis) = if let Some(fov) = p.float("fov")? {
        let axis_el = p.element_of("fov_axis");
        let axis = match p
            .string("fov_axis")?
            .unwrap_or("x")
            .to_ascii_lowercase()
            .as_str()
        {
            "x" => FovAxis::X,
            "y" => FovAxis::Y,
            "diagonal" => FovAxis::Diagonal,
            "smaller" => FovAxis::Smaller,
            "larger" => FovAxis::Larger,
            other => {
                return Err(axis_el.error(format!(
                    "unknown fov_axis \"{other}\" (use x, y, diagonal, smaller or larger)"
                )))
            }
        };
        (fov, axis)
    } else {
        let el = p.element_of("focal_length");
        let f = p.string("focal_length")?.unwrap_or("50mm");
        let mm = f.trim().strip_suffix("mm").unwrap_or(f).trim();
        let value: f64 = match mm.parse::<f64>() {
            Ok(v) if v > 0.0 && v.is_finite() => v,
            _ => {
                return Err(el.error(format!(
                    "could not parse focal length \"{f}\" (expected e.g. \"50mm\")"
                )))
            }
        };
        let fov = 2.0
            * ((36.0f64 * 36.0 + 24.0 * 24.0).sqrt() / (2.0 * value))
                .atan()
                .to_degrees();
        (fov, FovAxis::Diagonal)
    };
    if !(fov > 0.0 && fov < 180.0) {
        return Err(p.element_of("fov").error(format!(
            "the field of view must be in (0, 180) degrees, got {fov}"
        )));
    }
    Ok((fov, axis))
}

/// A `<film>`, `<sampler>` or `<rfilter>` declared outside a sensor, as Mitsuba allows. One that
/// a `<ref>` names is built where it is referenced; any other is checked (its errors are
/// reported, as Mitsuba instantiates it) and ignored with a warning (Mitsuba ignores it silently).
pub(super) fn build_detached<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<(), SceneError> {
    if el.attr("id").is_some_and(|id| b.is_referenced(id)) {
        return Ok(());
    }
    match el.tag.as_str() {
        "film" => {
            build_film(b, el)?;
        }
        "sampler" => {
            build_sampler(b, el)?;
        }
        _ => {
            build_rfilter(b, el)?;
        }
    }
    b.diag.warn(
        el,
        format!(
            "a <{}> outside a <sensor> that no <ref> names: ignored",
            el.tag
        ),
    );
    Ok(())
}

/// `hdrfilm`: width, height, the reconstruction filter and `sample_border`.
fn build_film<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<Film, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if kind != "hdrfilm" {
        let err = el.error(format!(
            "unknown plugin \"{kind}\" (supported films: hdrfilm)"
        ));
        b.diag.unknown(err)?;
    }
    let mut p = Props::parse(b, el)?;
    let mut side = |name: &str, default: u32| -> Result<u32, SceneError> {
        let e = p.element_of(name);
        match p.int(name)? {
            None => Ok(default),
            Some(v) if (1..=MAX_FILM_SIDE).contains(&v) => Ok(v as u32),
            Some(v) => Err(e.error(format!(
                "\"{name}\" must be in 1..={MAX_FILM_SIDE}, got {v}"
            ))),
        }
    };
    let width = side("width", DEFAULT_WIDTH)?;
    let height = side("height", DEFAULT_HEIGHT)?;
    let mut filter = FilterDesc::MITSUBA_DEFAULT;
    for obj in p.objects(&["rfilter", "ref"]) {
        let target = b.deref(obj)?;
        if target.tag != "rfilter" {
            return Err(obj.error(format!(
                "a film refers to an <rfilter>, not {}",
                target.describe()
            )));
        }
        filter = build_rfilter(b, target)?;
    }
    let sample_border = p.bool_or("sample_border", false)?;
    p.ignore(
        b,
        &[
            "pixel_format",
            "component_format",
            "file_format",
            "banner",
            "compensate",
        ],
        "the renderer writes float32 RGB",
    );
    let crop = if [
        "crop_offset_x",
        "crop_offset_y",
        "crop_width",
        "crop_height",
    ]
    .iter()
    .any(|name| p.has(name))
    {
        let mut number = |name: &str, default: u32, min: i64| -> Result<u32, SceneError> {
            let e = p.element_of(name);
            match p.int(name)? {
                None => Ok(default),
                Some(v) if (min..=MAX_FILM_SIDE).contains(&v) => Ok(v as u32),
                Some(v) => Err(e.error(format!(
                    "\"{name}\" must be in {min}..={MAX_FILM_SIDE}, got {v}"
                ))),
            }
        };
        let offset = glam::UVec2::new(
            number("crop_offset_x", 0, 0)?,
            number("crop_offset_y", 0, 0)?,
        );
        let size = glam::UVec2::new(
            number("crop_width", width, 1)?,
            number("crop_height", height, 1)?,
        );
        if offset.x + size.x > width || offset.y + size.y > height {
            return Err(el.error(format!(
                "the crop window (offset {}, {}, size {}×{}) does not fit inside the {width}×{height} film",
                offset.x, offset.y, size.x, size.y
            )));
        }
        Some(FilmCrop { offset, size })
    } else {
        None
    };
    p.finish(b)?;
    Ok(Film {
        width,
        height,
        filter,
        sample_border,
        crop,
    })
}

/// `<rfilter>`: `box`, `gaussian` (`stddev`), `tent` (`radius`), `mitchell` (`B`, `C`),
/// `catmullrom`, `lanczos` (`lobes`), with Mitsuba's defaults.
fn build_rfilter<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<FilterDesc, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let mut p = Props::parse(b, el)?;
    // A positive parameter that keeps the filter's support within a sane number of pixels.
    let width = |p: &mut Props, name: &str, default: f64, max: f64| {
        let e = p.element_of(name);
        match p.float(name)? {
            None => Ok(default as f32),
            Some(v) if v > 0.0 && v <= max => Ok(v as f32),
            Some(v) => Err(e.error(format!("\"{name}\" must be in (0, {max}], got {v}"))),
        }
    };
    let filter = match el.attr("type").unwrap_or_default() {
        "box" => FilterDesc::Box,
        "gaussian" => FilterDesc::Gaussian {
            stddev: width(&mut p, "stddev", 0.5, 8.0)?,
        },
        "tent" => FilterDesc::Tent {
            radius: width(&mut p, "radius", 1.0, 32.0)?,
        },
        "mitchell" => {
            let mut param = |name: &str| -> Result<f32, SceneError> {
                let e = p.element_of(name);
                match p.float(name)? {
                    None => Ok(1.0 / 3.0),
                    Some(v) if v.is_finite() && v.abs() <= 10.0 => Ok(v as f32),
                    Some(v) => Err(e.error(format!("\"{name}\" must be in [-10, 10], got {v}"))),
                }
            };
            let b_ = param("B")?;
            let c = param("C")?;
            FilterDesc::Mitchell { b: b_, c }
        }
        "catmullrom" => FilterDesc::Mitchell { b: 0.0, c: 0.5 },
        "lanczos" => {
            let e = p.element_of("lobes");
            match p.int("lobes")? {
                None => FilterDesc::Lanczos { lobes: 3 },
                Some(v) if (1..=32).contains(&v) => FilterDesc::Lanczos { lobes: v as u32 },
                Some(v) => return Err(e.error(format!("\"lobes\" must be in 1..=32, got {v}"))),
            }
        }
        other => {
            let err = el.error(format!(
                "unknown plugin \"{other}\" (supported rfilters: box, gaussian, tent, mitchell, catmullrom, lanczos)"
            ));
            b.diag.unknown(err)?;
            // Lenient mode: the project's own choice for unknown filters.
            FilterDesc::Box
        }
    };
    p.finish(b)?;
    Ok(filter)
}

/// Any of Mitsuba's samplers: only `sample_count` matters here (the renderer uses its own
/// deterministic per-pixel random streams).
fn build_sampler<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<u32, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    const SAMPLERS: [&str; 5] = [
        "independent",
        "stratified",
        "multijitter",
        "orthogonal",
        "ldsampler",
    ];
    if !SAMPLERS.contains(&kind) {
        let err = el.error(format!(
            "unknown plugin \"{kind}\" (supported samplers: {})",
            SAMPLERS.join(", ")
        ));
        b.diag.unknown(err)?;
    } else if kind != "independent" {
        b.diag.warn(el, "sampler treated as \"independent\"");
    }
    let mut p = Props::parse(b, el)?;
    let count = p.count("sample_count", 1)?.unwrap_or(4);
    p.ignore(
        b,
        &["seed", "jitter", "strength", "dimension"],
        "the renderer seeds its own random streams",
    );
    p.finish(b)?;
    Ok(count)
}

/// `direct`'s `emitter_samples` and `bsdf_samples`, as Mitsuba reads them: each defaults to
/// `shading_samples` (default 1), which must not be given together with either; not both 0.
fn direct_sample_counts(p: &mut Props, el: &Element) -> Result<(u32, u32), SceneError> {
    let shading = p.count("shading_samples", 0)?;
    let emitter = p.count("emitter_samples", 0)?;
    let bsdf = p.count("bsdf_samples", 0)?;
    if shading.is_some() && (emitter.is_some() || bsdf.is_some()) {
        return Err(el.error(
            "\"shading_samples\" sets both \"emitter_samples\" and \"bsdf_samples\"; give \
             either it or them"
                .to_owned(),
        ));
    }
    let shading = shading.unwrap_or(1);
    let counts = (emitter.unwrap_or(shading), bsdf.unwrap_or(shading));
    if counts == (0, 0) {
        return Err(
            el.error("the direct integrator needs at least one emitter or BSDF sample".to_owned())
        );
    }
    Ok(counts)
}

/// `<integrator>`: the plugin name, `max_depth`, `rr_depth`, `hide_emitters`, `direct`'s
/// sample counts, and an `aov`'s variables and nested integrators.
pub(super) fn build_integrator<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<IntegratorDesc, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    if kind == "aov" {
        return build_aov_integrator(b, el);
    }
    if !SAMPLING_INTEGRATORS.contains(&kind) && kind != "sppm" {
        let err = el.error(format!(
            "unknown plugin \"{kind}\" (supported integrators: {}, sppm, aov)",
            SAMPLING_INTEGRATORS.join(", ")
        ));
        b.diag.unknown(err)?;
    }
    // `volpath` and `volpathmis` are the volumetric path tracer (`render` chooses it for them;
    // the two differ only in how they sample), the differentiable `prb` and `prb_basic` are
    // `path` when rendering forward; `sppm` is the integrator chosen on the command line anyway.
    let mut p = Props::parse(b, el)?;
    let depth_el = p.element_of("max_depth");
    let max_depth = match p.int("max_depth")? {
        None => -1,
        Some(v) if v >= -1 && v <= i64::from(i32::MAX) => v as i32,
        Some(v) => {
            return Err(depth_el.error(format!(
                "\"max_depth\" must be -1 (unbounded) or >= 0, got {v}"
            )))
        }
    };
    let rr_depth = p.count("rr_depth", 0)?.unwrap_or(5);
    let hide_emitters = p.bool_or("hide_emitters", false)?;
    let (emitter_samples, bsdf_samples) = direct_sample_counts(&mut p, el)?;
    p.ignore(
        b,
        &[
            "photon_count",
            "initial_radius",
            "alpha",
            "samples_per_pass",
            "timeout",
        ],
        "set on the command line / in the config instead",
    );
    p.ignore(b, &["block_size"], "the renderer schedules its own work");
    p.finish(b)?;
    Ok(IntegratorDesc {
        kind: kind.to_owned(),
        max_depth,
        rr_depth,
        hide_emitters,
        emitter_samples,
        bsdf_samples,
        ..IntegratorDesc::default()
    })
}

/// The integrators an `aov` integrator can nest: those that estimate radiance along camera
/// rays (Mitsuba's sampling integrators).
const SAMPLING_INTEGRATORS: [&str; 7] = [
    "path",
    "volpath",
    "volpathmis",
    "prb",
    "prb_basic",
    "direct",
    "depth",
];

/// Mitsuba's `aov`: `aovs` (required: `<name>:<kind>` pairs separated by commas) and the
/// nested integrators whose images come with the variables (their layers are named by their
/// `name`, else `_arg_<k>` for the k-th unnamed one, as Mitsuba names them). The depth settings
/// and `hide_emitters` are the first nested integrator's (what the other tools read from the
/// file); nested integrators that differ in `hide_emitters` are refused, since the scene has
/// one such setting.
fn build_aov_integrator<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<IntegratorDesc, SceneError> {
    let mut p = Props::parse(b, el)?;
    let aovs_el = p.element_of("aovs");
    let Some(spec) = p.string("aovs")? else {
        return Err(el.error("missing parameter \"aovs\" (e.g. \"dd:depth,nn:sh_normal\")"));
    };
    let mut aovs = Vec::new();
    for item in spec.split(',').map(str::trim).filter(|t| !t.is_empty()) {
        let (name, kind) = item.split_once(':').unwrap_or((item, ""));
        let (name, kind) = (name.trim(), kind.trim());
        if name.is_empty() || kind.is_empty() || kind.contains(':') {
            return Err(aovs_el.error(format!("\"aovs\": \"{item}\" is not a <name>:<kind> pair")));
        }
        if kind == "boundary_test" {
            return Err(aovs_el.error(
                "\"aovs\": the AOV kind \"boundary_test\" (differentiable rendering's \
                 distance to silhouettes) is not supported",
            ));
        }
        let Some(kind) = crate::description::AovKind::from_name(kind) else {
            return Err(aovs_el.error(format!(
                "\"aovs\": unknown AOV kind \"{kind}\" (known: {})",
                crate::description::AovKind::NAMES.join(", ")
            )));
        };
        aovs.push(crate::description::AovSpec {
            name: name.to_owned(),
            kind,
        });
    }
    let mut nested = Vec::new();
    let mut unnamed = 0;
    for obj in p.objects(&["integrator", "ref"]) {
        let target = b.deref(obj)?;
        if target.tag != "integrator" {
            return Err(obj.error(format!(
                "an aov integrator holds <integrator>s, not {}",
                target.describe()
            )));
        }
        let inner = build_integrator(b, target)?;
        if !SAMPLING_INTEGRATORS.contains(&inner.kind.as_str()) {
            return Err(target.error(format!(
                "an aov integrator nests sampling integrators ({}), not \"{}\"",
                SAMPLING_INTEGRATORS.join(", "),
                inner.kind
            )));
        }
        let name = match obj.attr("name") {
            Some(n) if !n.is_empty() => n.to_owned(),
            Some(_) => return Err(obj.error("a nested integrator's \"name\" is empty")),
            None => {
                unnamed += 1;
                format!("_arg_{}", unnamed - 1)
            }
        };
        nested.push((name, inner));
    }
    p.finish(b)?;
    if aovs.is_empty() && nested.is_empty() {
        return Err(el.error("an aov integrator needs AOVs or a nested integrator"));
    }
    // Every channel of the image once: `R`, `G`, `B`, each nested image's `<name>.R…A` and
    // each variable's `<name>.<suffix>`.
    let mut channels: Vec<String> = ["R", "G", "B"].map(String::from).to_vec();
    for (name, _) in &nested {
        channels.extend(["R", "G", "B", "A"].map(|c| format!("{name}.{c}")));
    }
    for aov in &aovs {
        channels.extend(
            aov.kind
                .suffixes()
                .iter()
                .map(|c| format!("{}.{c}", aov.name)),
        );
    }
    for (i, c) in channels.iter().enumerate() {
        // OpenEXR's limit; a longer name makes a file other readers refuse.
        if c.len() > 255 {
            return Err(el.error(format!(
                "the channel name \"{c}\" is {} bytes long: OpenEXR allows at most 255",
                c.len()
            )));
        }
        if channels[..i].contains(c) {
            return Err(aovs_el.error(format!(
                "two outputs of the aov integrator write the channel \"{c}\": give them \
                 different names"
            )));
        }
    }
    if let Some((name, _)) = nested
        .iter()
        .find(|(_, n)| n.hide_emitters != nested[0].1.hide_emitters)
    {
        return Err(el.error(format!(
            "the nested integrators differ in \"hide_emitters\" (\"{name}\" and \"{}\"): \
             this renderer has one such setting per scene",
            nested[0].0
        )));
    }
    let first = nested.first().map(|(_, n)| n.clone()).unwrap_or_default();
    Ok(IntegratorDesc {
        kind: "aov".into(),
        max_depth: first.max_depth,
        rr_depth: first.rr_depth,
        hide_emitters: first.hide_emitters,
        emitter_samples: first.emitter_samples,
        bsdf_samples: first.bsdf_samples,
        aovs,
        nested,
    })
}
