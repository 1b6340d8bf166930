//! `<texture>` plugins: `checkerboard`, `bitmap` (PNG, JPEG, TGA, BMP, PPM, HDR, PFM or EXR: `image_io`; paths looked up as Mitsuba's file resolver does)
//! and `mesh_attribute` (bound to the mesh of the shape being built).

use super::props::Props;
use super::{Builder, Element, SceneError};
use crate::image_io;
use crate::spectrum::SpectrumKind;
use crate::texture::{Bitmap, BitmapFilter, BitmapWrap, Texture};
use glam::{Mat3, Mat4};
use std::sync::Arc;

/// Builds the texture declared by a `<texture>` element.
pub(super) fn build_texture<'a>(
    b: &mut Builder<'a>,
    el: &'a Element,
) -> Result<Texture, SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    let mut p = Props::parse(b, el)?;
    let tex = match kind {
        "checkerboard" => {
            let refl = SpectrumKind::Reflectance;
            let color0 = p
                .constant_color(b, "color0", refl)?
                .unwrap_or(glam::Vec3::splat(0.4));
            let color1 = p
                .constant_color(b, "color1", refl)?
                .unwrap_or(glam::Vec3::splat(0.2));
            Texture::Checkerboard {
                color0,
                color1,
                to_uv: to_uv(&mut p)?,
            }
        }
        "bitmap" => {
            let file_el = p.element_of("filename");
            let Some(filename) = p.string("filename")? else {
                return Err(el.error("missing parameter \"filename\""));
            };
            let raw = p.bool_or("raw", false)?;
            let filter_el = p.element_of("filter_type");
            let filter = match p.string("filter_type")?.unwrap_or("bilinear") {
                "bilinear" => BitmapFilter::Bilinear,
                "nearest" => BitmapFilter::Nearest,
                other => {
                    return Err(filter_el.error(format!(
                        "unknown filter_type \"{other}\" (use \"bilinear\" or \"nearest\")"
                    )))
                }
            };
            let wrap = wrap_mode(&mut p, "repeat")?;
            let to_uv = to_uv(&mut p)?;
            // Mitsuba's storage precision and GPU texture units: the texels are kept in single
            // precision here, and filtered in software.
            let format_el = p.element_of("format");
            match p.string("format")? {
                None | Some("auto" | "variant") => {}
                Some(f @ ("float16" | "fp16" | "uint8")) => b.diag.warn(
                    format_el,
                    format!("format \"{f}\" ignored: texels are stored in single precision"),
                ),
                Some(other) => {
                    return Err(format_el.error(format!(
                        "invalid format \"{other}\" (use \"auto\", \"variant\", \"float16\" or \"uint8\")"
                    )))
                }
            }
            p.bool_or("accel", true)?;
            let image = load_bitmap(b, file_el, filename, raw)?;
            Texture::Bitmap {
                image,
                filter,
                wrap,
                to_uv,
            }
        }
        "mesh_attribute" => {
            let name_el = p.element_of("name");
            let Some(name) = p.string("name")? else {
                return Err(el.error("missing parameter \"name\" (e.g. \"vertex_color\")"));
            };
            // Mitsuba only checks that the name contains one of the prefixes; attribute names
            // always start with them, so any other name would find nothing.
            if !(name.starts_with("vertex_") || name.starts_with("face_")) {
                return Err(name_el.error(format!(
                    "invalid mesh attribute name \"{name}\": it must start with \"vertex_\" or \"face_\""
                )));
            }
            let scale_el = p.element_of("scale");
            let scale = p.float_or("scale", 1.0)? as f32;
            if !scale.is_finite() {
                return Err(scale_el.error("\"scale\" must be finite"));
            }
            let values = b.bind_mesh_attribute(el, name)?;
            Texture::MeshAttribute { values, scale }
        }
        other => {
            let err = el.error(format!(
                "unknown plugin \"{other}\" (supported textures: checkerboard, bitmap, mesh_attribute)"
            ));
            b.diag.unknown(err)?;
            return Ok(Texture::Constant(glam::Vec3::splat(0.5)));
        }
    };
    p.finish(b)?;
    Ok(tex)
}

/// The image `filename` (relative to the file of `file_el`), linear RGB, loaded once per
/// scene for each (path, `raw`) however many plugins use it.
pub(super) fn load_bitmap<'a>(
    b: &mut Builder<'a>,
    file_el: &Element,
    filename: &str,
    raw: bool,
) -> Result<Arc<Bitmap>, SceneError> {
    let path = file_el.resolve_path(filename, &b.diag.search_paths);
    let key = (path.clone(), raw);
    if let Some(img) = b.bitmaps.get(&key) {
        return Ok(img.clone());
    }
    let (width, height, texels) = image_io::read_rgb_image_encoded(&path, raw)
        .map_err(|e| file_el.error(format!("cannot load bitmap: {e}")))?;
    if texels.is_empty() {
        return Err(file_el.error(format!("bitmap \"{}\" is empty", path.display())));
    }
    let img = Arc::new(Bitmap {
        width,
        height,
        texels,
    });
    b.bitmaps.insert(key, img.clone());
    Ok(img)
}

/// `to_uv`: Mitsuba takes the 2-D affine part (x/y rows and columns plus the translation) of
/// the 4×4 transform written in the file.
fn to_uv(p: &mut Props) -> Result<Mat3, SceneError> {
    Ok(p.transform("to_uv")?
        .map(uv_affine)
        .unwrap_or(Mat3::IDENTITY))
}

/// The 2-D affine part of a 4×4 transform, as a 3×3 matrix acting on (u, v, 1).
pub(crate) fn uv_affine(m: Mat4) -> Mat3 {
    Mat3::from_cols(
        glam::Vec3::new(m.x_axis.x, m.x_axis.y, 0.0),
        glam::Vec3::new(m.y_axis.x, m.y_axis.y, 0.0),
        glam::Vec3::new(m.w_axis.x, m.w_axis.y, 1.0),
    )
}

/// The `wrap_mode` parameter of a bitmap or a grid volume (`repeat`, `mirror`, `clamp`),
/// `default` when absent.
pub(super) fn wrap_mode(p: &mut Props, default: &str) -> Result<BitmapWrap, SceneError> {
    let wrap_el = p.element_of("wrap_mode");
    match p.string("wrap_mode")?.unwrap_or(default) {
        "repeat" => Ok(BitmapWrap::Repeat),
        "mirror" => Ok(BitmapWrap::Mirror),
        "clamp" => Ok(BitmapWrap::Clamp),
        other => Err(wrap_el.error(format!(
            "unknown wrap_mode \"{other}\" (use \"repeat\", \"mirror\" or \"clamp\")"
        ))),
    }
}
