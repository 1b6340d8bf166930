//! Mesh attributes (Mitsuba's `vertex_*` / `face_*`) for the `mesh_attribute` texture: which
//! extra PLY properties become attributes and how their values are converted (as Mitsuba
//! 3.9.1's PLY loader does, quirks included), and binding an attribute to the triangles of the
//! shape whose BSDF or area emitter reads it.
//!
//! Mitsuba 3.9.1's rules, measured with its `llvm_ad_rgb` variant (see docs/validation.md):
//! - `r`, `g`, `b` (or `red`, `green`, `blue`, then also `alpha`) form `vertex_color` /
//!   `face_color` (3 channels, 4 with `a`/`alpha`);
//! - other properties named `{prefix}_{postfix}` with a one-letter postfix are grouped, in file
//!   order, into `vertex_{prefix}` / `face_{prefix}` when consecutive and following one of the
//!   sequences `x y z w`, `r g b a` (named `{prefix}_color` then), `0 1 2 3` or `1 2 3 4`;
//!   only groups of 1 or 3 properties are kept, a prefix is used once;
//! - values: `float`/`double` as they are, `uchar` **unnormalised** (0–255, Mitsuba's converter
//!   ignores the normalisation it requests for 8-bit unsigned fields), every other integer type
//!   divided by its largest value and then decoded from sRGB to linear (negative values take
//!   the linear branch, x / 12.92).

use crate::texture::AttributeValues;
use ply_rs_bw::ply::{Property, PropertyType};
use std::collections::HashSet;
use std::sync::Arc;

/// One extra property of a PLY element, as the grouping sees it.
#[derive(Debug, Clone)]
pub(super) struct PlyField {
    /// Property name.
    pub name: String,
    /// A list property (never part of an attribute; it ends a group, as in Mitsuba).
    pub list: bool,
}

impl PlyField {
    /// The fields of a PLY element definition, in file order.
    pub fn of(def: &ply_rs_bw::ply::ElementDef) -> Vec<PlyField> {
        def.properties
            .values()
            .map(|p| PlyField {
                name: p.name.clone(),
                list: matches!(p.data_type, PropertyType::List(..)),
            })
            .collect()
    }
}

/// An attribute found in a PLY element: its name and the properties of its channels.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct AttributeSource {
    /// Full name, `vertex_…` or `face_…`.
    pub name: String,
    /// Property names, one per channel.
    pub properties: Vec<String>,
}

/// Postfix sequences: channel `k` of a group in category `c` has postfix `POSTFIXES[k][c]`.
const POSTFIXES: [[u8; 4]; 4] = [*b"xr01", *b"yg12", *b"zb23", *b"wa34"];

/// The attributes Mitsuba 3.9.1 makes of an element's properties (`kind` is `"vertex_"` or
/// `"face_"`; `reserved` are properties the loader already reads: positions, normals, uvs).
pub(super) fn group_attributes(
    kind: &str,
    fields: &[PlyField],
    reserved: &[&str],
) -> Vec<AttributeSource> {
    let has = |n: &str| fields.iter().any(|f| f.name == n && !f.list);
    let mut out = Vec::new();
    // The colour first, wherever its properties are; `alpha` only joins `red green blue`.
    let colour = if has("r") && has("g") && has("b") {
        Some(["r", "g", "b", "a"])
    } else if has("red") && has("green") && has("blue") {
        Some(["red", "green", "blue", "alpha"])
    } else {
        None
    };
    let mut skip: Vec<&str> = reserved.to_vec();
    skip.extend(["r", "g", "b", "a"]);
    if let Some(names) = colour {
        let n = if has(names[3]) { 4 } else { 3 };
        out.push(AttributeSource {
            name: format!("{kind}color"),
            properties: names[..n].iter().map(|s| s.to_string()).collect(),
        });
        skip.extend(names);
    }

    // Mitsuba's state machine over the remaining properties, step for step (including its
    // habit of also passing over the property that follows a skipped run of one prefix).
    let mut g = Grouping {
        kind,
        out,
        seen: HashSet::new(),
        group: None,
        level: 0,
    };
    let skip_run = |i: &mut usize, prefix: &str| {
        while *i < fields.len() && fields[*i].name.starts_with(prefix) {
            *i += 1;
        }
    };
    let mut i = 0;
    while i < fields.len() {
        let f = &fields[i];
        if !f.list && skip.contains(&f.name.as_str()) {
            i += 1;
            continue;
        }
        let split = if f.list { None } else { f.name.rfind('_') };
        let Some((prefix, postfix)) = split.map(|p| (&f.name[..p], &f.name[p + 1..])) else {
            g.flush();
            i += 1;
            continue;
        };
        let &[c] = postfix.as_bytes() else {
            g.flush();
            i += 1;
            continue;
        };
        if g.group.as_ref().is_some_and(|(p, _)| p != prefix) {
            g.flush();
        }
        match &g.group {
            None if g.seen.contains(prefix) => {
                skip_run(&mut i, prefix);
                i += 1;
                continue;
            }
            None => match POSTFIXES[0].iter().position(|&x| x == c) {
                Some(cat) => g.group = Some((prefix.to_owned(), cat)),
                None => {
                    i += 1;
                    continue;
                }
            },
            Some((_, cat)) => {
                if POSTFIXES.get(g.level).map(|row| row[*cat]) != Some(c) {
                    // An invalid sequence drops the group; Mitsuba does not reset its channel
                    // count here, so the count carries on into the next group.
                    g.group = None;
                    g.level = 0;
                    skip_run(&mut i, prefix);
                    if i == fields.len() {
                        break;
                    }
                }
            }
        }
        g.level += 1;
        i += 1;
    }
    g.flush();
    g.out
}

/// The state of [`group_attributes`]'s pass over the properties.
struct Grouping<'k> {
    /// `"vertex_"` or `"face_"`.
    kind: &'k str,
    /// Attributes found so far.
    out: Vec<AttributeSource>,
    /// Prefixes already made into attributes.
    seen: HashSet<String>,
    /// The group being read: its prefix and postfix category.
    group: Option<(String, usize)>,
    /// Properties counted into the current group.
    level: usize,
}

impl Grouping<'_> {
    /// Ends the current group, if any: kept with 1 or 3 channels, dropped otherwise.
    fn flush(&mut self) {
        if let Some((prefix, cat)) = self.group.take() {
            if self.level == 1 || self.level == 3 {
                let suffix = if cat == 1 { "_color" } else { "" };
                self.out.push(AttributeSource {
                    name: format!("{}{prefix}{suffix}", self.kind),
                    properties: (0..self.level)
                        .map(|k| format!("{prefix}_{}", POSTFIXES[k][cat] as char))
                        .collect(),
                });
                self.seen.insert(prefix);
            }
            self.level = 0;
        }
    }
}

/// A PLY property value as Mitsuba 3.9.1 stores it in an attribute (see the module comment);
/// `None` for lists.
pub(super) fn attribute_value(p: &Property) -> Option<f32> {
    let unit = |v: f64, max: f64| fileio::srgb::decode_f64(v / max) as f32;
    Some(match *p {
        Property::Float(v) => v,
        Property::Double(v) => v as f32,
        Property::UChar(v) => v as f32,
        Property::Char(v) => unit(v as f64, i8::MAX as f64),
        Property::Short(v) => unit(v as f64, i16::MAX as f64),
        Property::UShort(v) => unit(v as f64, u16::MAX as f64),
        Property::Int(v) => unit(v as f64, i32::MAX as f64),
        Property::UInt(v) => unit(v as f64, u32::MAX as f64),
        _ => return None,
    })
}

/// An attribute as loaded: `channels` numbers per vertex, or per polygon of the file.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RawAttribute {
    /// Full name, `vertex_…` or `face_…`.
    pub name: String,
    /// Numbers per element.
    pub channels: usize,
    /// The numbers, element after element.
    pub values: Vec<f32>,
}

impl RawAttribute {
    /// Whether the attribute is per face (constant over each polygon).
    pub fn per_face(&self) -> bool {
        self.name.starts_with("face_")
    }
}

/// The attributes of one loaded mesh, with what binding needs to lay them out per triangle.
#[derive(Debug, Clone, Default)]
pub(crate) struct MeshAttributes {
    /// The attributes, in file order.
    pub(crate) attributes: Vec<RawAttribute>,
    /// The mesh's final triangles (after fan triangulation).
    pub(crate) triangles: Vec<[u32; 3]>,
    /// For each triangle, the file polygon it was cut from.
    pub(crate) polygon_of: Vec<u32>,
}

impl MeshAttributes {
    /// Attribute `name` laid out per triangle, or a message saying why it cannot be read.
    pub(crate) fn bind(&self, name: &str) -> Result<Arc<AttributeValues>, String> {
        let Some(a) = self.attributes.iter().find(|a| a.name == name) else {
            let names: Vec<&str> = self.attributes.iter().map(|a| a.name.as_str()).collect();
            return Err(if names.is_empty() {
                format!("the mesh has no attribute \"{name}\" (it has no attributes at all)")
            } else {
                format!(
                    "the mesh has no attribute \"{name}\" (it has: {})",
                    names.join(", ")
                )
            });
        };
        let ch = a.channels;
        if ch != 1 && ch != 3 {
            // Mitsuba 3.9.1: an error in scalar variants, silently zero in JIT variants.
            return Err(format!(
                "attribute \"{name}\" has {ch} channels; mesh_attribute reads 1- or 3-channel \
                 attributes only"
            ));
        }
        let per_face = a.per_face();
        let values = if per_face {
            self.polygon_of
                .iter()
                .flat_map(|&f| &a.values[f as usize * ch..(f as usize + 1) * ch])
                .copied()
                .collect()
        } else {
            self.triangles
                .iter()
                .flatten()
                .flat_map(|&v| &a.values[v as usize * ch..(v as usize + 1) * ch])
                .copied()
                .collect()
        };
        Ok(Arc::new(AttributeValues {
            name: name.to_owned(),
            channels: ch,
            per_face,
            values,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields(names: &[&str]) -> Vec<PlyField> {
        names
            .iter()
            .map(|n| PlyField {
                name: n.to_string(),
                list: *n == "vertex_indices",
            })
            .collect()
    }

    fn grouped(kind: &str, names: &[&str]) -> Vec<(String, Vec<String>)> {
        group_attributes(
            kind,
            &fields(names),
            &["x", "y", "z", "nx", "ny", "nz", "u", "v"],
        )
        .into_iter()
        .map(|a| (a.name, a.properties))
        .collect()
    }

    fn strings(s: &[&str]) -> Vec<String> {
        s.iter().map(|x| x.to_string()).collect()
    }

    /// The groupings Mitsuba 3.9.1 makes (checked against `mi.load_dict` on PLY files with
    /// these headers): colours, 1- and 3-channel groups, the `_color` suffix of r/g/b postfixes,
    /// groups of other sizes dropped, a repeated prefix ignored.
    #[test]
    fn ply_properties_group_like_mitsuba() {
        assert_eq!(
            grouped(
                "vertex_",
                &["x", "y", "z", "red", "green", "blue", "alpha", "u", "v"]
            ),
            [(
                "vertex_color".into(),
                strings(&["red", "green", "blue", "alpha"])
            )]
        );
        assert_eq!(
            grouped("vertex_", &["x", "r", "g", "b", "alpha", "rough_x"]),
            [
                ("vertex_color".into(), strings(&["r", "g", "b"])),
                ("vertex_rough".into(), strings(&["rough_x"])),
            ]
        );
        assert_eq!(
            grouped(
                "face_",
                &[
                    "vertex_indices",
                    "fc_r",
                    "fc_g",
                    "fc_b",
                    "w_0",
                    "d_1",
                    "d_2",
                    "d_3"
                ]
            ),
            [
                ("face_fc_color".into(), strings(&["fc_r", "fc_g", "fc_b"])),
                ("face_w".into(), strings(&["w_0"])),
                ("face_d".into(), strings(&["d_1", "d_2", "d_3"])),
            ]
        );
        // Two channels: dropped; a prefix seen before: dropped (with the property after it).
        assert_eq!(
            grouped(
                "vertex_",
                &["q_x", "q_y", "s_x", "k_0", "s_y", "m_x", "n_x"]
            ),
            [
                ("vertex_s".into(), strings(&["s_x"])),
                ("vertex_k".into(), strings(&["k_0"])),
                ("vertex_n".into(), strings(&["n_x"])),
            ]
        );
        // A broken sequence drops its group and the property after it, and its channel count
        // carries on, so `c_0 c_1` reads as a broken sequence too.
        assert!(grouped("vertex_", &["a_x", "a_z", "b_x", "c_0", "c_1"]).is_empty());
        // Names without a one-letter postfix are not attributes.
        assert!(grouped("vertex_", &["quality", "flag_xy"]).is_empty());
    }

    /// Value conversion as Mitsuba 3.9.1 stores it (numbers read back from its
    /// `attribute_buffer`): uchar unnormalised, other integers normalised then sRGB-decoded.
    #[test]
    fn ply_values_convert_like_mitsuba() {
        let v = |p: Property| attribute_value(&p).unwrap();
        assert_eq!(v(Property::UChar(128)), 128.0);
        assert_eq!(v(Property::Float(0.25)), 0.25);
        assert_eq!(v(Property::Double(3.0)), 3.0);
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * b.abs().max(1e-3);
        assert!(close(v(Property::Char(-128)), -0.078_008_82));
        assert!(close(v(Property::Char(127)), 1.0));
        assert!(close(v(Property::Char(64)), 0.217_703_16));
        assert!(close(v(Property::UShort(32768)), 0.214_048_09));
        assert!(close(v(Property::Short(-32768)), -0.077_401_74));
        assert!(close(v(Property::Int(1_073_741_824)), 0.214_041_07));
        assert!(close(v(Property::UInt(1)), 1.802_094_8e-11));
        assert_eq!(attribute_value(&Property::ListInt(vec![1])), None);
    }

    /// Binding lays vertex values out per triangle corner (following the final winding) and
    /// face values per triangle (repeated over a fan-triangulated polygon).
    #[test]
    fn binding_lays_values_out_per_triangle() {
        let mesh = MeshAttributes {
            attributes: vec![
                RawAttribute {
                    name: "vertex_w".into(),
                    channels: 1,
                    values: vec![10.0, 11.0, 12.0, 13.0],
                },
                RawAttribute {
                    name: "face_color".into(),
                    channels: 3,
                    values: vec![0.1, 0.2, 0.3],
                },
                RawAttribute {
                    name: "vertex_color".into(),
                    channels: 4,
                    values: vec![0.0; 16],
                },
            ],
            triangles: vec![[0, 2, 1], [0, 3, 2]],
            polygon_of: vec![0, 0],
        };
        let w = mesh.bind("vertex_w").unwrap();
        assert_eq!((w.channels, w.per_face), (1, false));
        assert_eq!(w.values, [10.0, 12.0, 11.0, 10.0, 13.0, 12.0]);
        let c = mesh.bind("face_color").unwrap();
        assert!(c.per_face);
        assert_eq!(c.values, [0.1, 0.2, 0.3, 0.1, 0.2, 0.3]);
        let missing = mesh.bind("vertex_nope").unwrap_err();
        assert!(
            missing.contains("vertex_w, face_color, vertex_color"),
            "{missing}"
        );
        assert!(mesh
            .bind("vertex_color")
            .unwrap_err()
            .contains("4 channels"));
    }
}
