//! `<transform>` elements: `translate`, `rotate`, `scale`, `matrix` and `lookat`, composed in
//! file order as Mitsuba does (each new operation is multiplied from the left, so the first
//! one written is applied to the object first). Computed in double precision.

use super::props::{parse_float, parse_floats};
use super::{Diagnostics, Element, SceneError};
use glam::{DMat4, DVec3, DVec4, Mat4};

/// Parses the operations inside a `<transform>` into one matrix.
pub(crate) fn parse_transform(el: &Element, diag: &mut Diagnostics) -> Result<Mat4, SceneError> {
    let mut m = DMat4::IDENTITY;
    for op in &el.children {
        let t = match op.tag.as_str() {
            "translate" => {
                op.check_attributes(&["x", "y", "z", "value"], &[], diag)?;
                DMat4::from_translation(xyz_or_value(op, 0.0)?)
            }
            "scale" => {
                op.check_attributes(&["x", "y", "z", "value"], &[], diag)?;
                DMat4::from_scale(xyz_or_value(op, 1.0)?)
            }
            "rotate" => {
                op.check_attributes(&["x", "y", "z", "value", "angle"], &["angle"], diag)?;
                let axis = xyz_or_value(op, 0.0)?;
                let angle = parse_float(op, op.attr("angle").unwrap_or_default())?;
                if axis.length_squared() == 0.0 {
                    return Err(op.error("rotation axis is zero"));
                }
                DMat4::from_axis_angle(axis.normalize(), angle.to_radians())
            }
            "matrix" => {
                op.check_attributes(&["value"], &["value"], diag)?;
                let v = parse_floats(op, op.attr("value").unwrap_or_default())?;
                match v.len() {
                    // Row-major, as written in the file.
                    16 => DMat4::from_cols_array(&[
                        v[0], v[4], v[8], v[12], v[1], v[5], v[9], v[13], v[2], v[6], v[10], v[14],
                        v[3], v[7], v[11], v[15],
                    ]),
                    9 => DMat4::from_cols(
                        DVec4::new(v[0], v[3], v[6], 0.0),
                        DVec4::new(v[1], v[4], v[7], 0.0),
                        DVec4::new(v[2], v[5], v[8], 0.0),
                        DVec4::W,
                    ),
                    n => return Err(op.error(format!("<matrix> needs 16 (or 9) values, got {n}"))),
                }
            }
            "lookat" => {
                op.check_attributes(&["origin", "target", "up"], &["origin", "target"], diag)?;
                let origin = vec3_attr(op, "origin")?;
                let target = vec3_attr(op, "target")?;
                let up = match op.attr("up") {
                    Some(_) => Some(vec3_attr(op, "up")?),
                    None => None,
                };
                look_at(op, origin, target, up)?
            }
            other => {
                diag.unknown(op.error(format!("unknown transform operation <{other}>")))?;
                continue;
            }
        };
        m = t * m;
    }
    let out = m.as_mat4();
    if !out.is_finite() {
        return Err(el.error("transform is not finite"));
    }
    Ok(out)
}

/// Mitsuba's look-at frame: columns (left, up', dir, origin) with dir = normalize(target −
/// origin), left = normalize(up × dir), up' = dir × left. The camera looks along its local +z.
pub fn look_at_matrix(origin: DVec3, target: DVec3, up: DVec3) -> Option<DMat4> {
    let dir = (target - origin).try_normalize()?;
    let left = up.cross(dir).try_normalize()?;
    let new_up = dir.cross(left);
    Some(DMat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        origin.extend(1.0),
    ))
}

fn look_at(
    op: &Element,
    origin: DVec3,
    target: DVec3,
    up: Option<DVec3>,
) -> Result<DMat4, SceneError> {
    let dir = (target - origin)
        .try_normalize()
        .ok_or_else(|| op.error("lookat: origin and target coincide"))?;
    // Without an `up` (or with a zero one) Mitsuba takes the first vector of its
    // `coordinate_system(dir)` (`crate::math::coordinate_system`, here in double precision as
    // its parser computes it). Any perpendicular vector makes a valid frame, but the frame
    // orients the picture: a camera's image, a spot light's projected texture.
    let up = match up {
        Some(up) if up != DVec3::ZERO => up,
        _ => {
            let sign = 1.0f64.copysign(dir.z);
            let a = -1.0 / (sign + dir.z);
            DVec3::new(
                1.0 + sign * dir.x * dir.x * a,
                sign * dir.x * dir.y * a,
                -sign * dir.x,
            )
        }
    };
    look_at_matrix(origin, target, up)
        .ok_or_else(|| op.error("lookat: the up vector is parallel to the view direction"))
}

/// A vector from `x`/`y`/`z` attributes (missing ones = `default`) or from `value` (one number
/// for all three components, or three numbers).
fn xyz_or_value(op: &Element, default: f64) -> Result<DVec3, SceneError> {
    if let Some(s) = op.attr("value") {
        if op.attr("x").is_some() || op.attr("y").is_some() || op.attr("z").is_some() {
            return Err(op.error("give either \"value\" or x/y/z, not both"));
        }
        let v = parse_floats(op, s)?;
        return match v.as_slice() {
            [a] => Ok(DVec3::splat(*a)),
            [a, b, c] => Ok(DVec3::new(*a, *b, *c)),
            _ => Err(op.error(format!(
                "\"value\" needs one or three numbers, got {}",
                v.len()
            ))),
        };
    }
    let get = |k: &str| {
        op.attr(k)
            .map(|s| parse_float(op, s))
            .unwrap_or(Ok(default))
    };
    Ok(DVec3::new(get("x")?, get("y")?, get("z")?))
}

/// A three-component attribute like `origin="1, 2, 3"`.
fn vec3_attr(op: &Element, name: &str) -> Result<DVec3, SceneError> {
    let v = parse_floats(op, op.attr(name).unwrap_or_default())?;
    match v.as_slice() {
        [a, b, c] => Ok(DVec3::new(*a, *b, *c)),
        _ => Err(op.error(format!(
            "attribute \"{name}\" needs three numbers, got {}",
            v.len()
        ))),
    }
}
