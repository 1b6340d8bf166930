//! PLY meshes for `<shape type="ply">` (ASCII or binary), read into a [`RawMesh`]: positions,
//! normals, uvs, polygons, and the extra properties that become mesh attributes
//! (`mesh_attributes.rs`).

use super::mesh_attributes::{
    attribute_value, group_attributes, AttributeSource, PlyField, RawAttribute,
};
use super::mesh_file::RawMesh;
use glam::{Vec2, Vec3};
use std::path::Path;

/// Reads a PLY (ASCII or binary) with `vertex` (x, y, z, optional nx/ny/nz and u/v, s/t or
/// texture_u/texture_v) and `face` (`vertex_indices` or `vertex_index`) elements.
/// Other vertex and face properties become attributes as Mitsuba 3.9.1 groups them.
/// Elements are read and converted one at a time: holding the whole payload as parsed
/// elements (a map of named properties each) took ~500 bytes per triangle.
pub(crate) fn load_ply(path: &Path) -> Result<RawMesh, String> {
    use ply_rs_bw::parser::{Parser, Reader};
    use ply_rs_bw::ply::{DefaultElement, Encoding, Property};
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    // Each element takes at least one byte: counts past the file's size are not reserved for.
    let file_len = file.metadata().map_or(0, |m| m.len()) as usize;
    let mut reader = Reader::new(std::io::BufReader::new(file));
    let parser = Parser::<DefaultElement>::new();
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| format!("invalid PLY: {e}"))?;
    let scalar =
        |e: &DefaultElement, k: &str| -> Option<f32> { e.get(k).and_then(|p| p.to_f32_lossy()) };
    let vertex_def = header
        .elements
        .get("vertex")
        .ok_or("no \"vertex\" element")?;
    if !header.elements.contains_key("face") {
        return Err("no \"face\" element".into());
    }
    let mut raw = RawMesh::default();
    let has = |k: &str| vertex_def.count > 0 && vertex_def.properties.contains_key(k);
    let has_normals = has("nx") && has("ny") && has("nz");
    let uv_keys = [
        ("u", "v"),
        ("s", "t"),
        ("texture_u", "texture_v"),
        ("texture_s", "texture_t"),
    ]
    .into_iter()
    .find(|(u, v)| has(u) && has(v));
    // Mitsuba reserves x, y, z, nx, ny, nz and the uv pair it reads (renamed u, v).
    let mut reserved = vec!["x", "y", "z", "nx", "ny", "nz", "u", "v"];
    reserved.extend(uv_keys.iter().flat_map(|(u, v)| [*u, *v]));
    let fields = |name: &str| {
        header
            .elements
            .get(name)
            .map(PlyField::of)
            .unwrap_or_default()
    };
    let vertex_sources = group_attributes("vertex_", &fields("vertex"), &reserved);
    let face_sources = group_attributes("face_", &fields("face"), &[]);
    let mut vertex_attributes = new_attributes(&vertex_sources);
    let mut face_attributes = new_attributes(&face_sources);
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    // One face's indices (reused across faces).
    let mut idx: Vec<i64> = Vec::new();
    let mut line = String::new();
    // In file order: every element is read, those other than vertices and faces skipped.
    for def in header.elements.values() {
        let kind = def.name.as_str();
        if kind == "vertex" {
            let n = def.count.min(file_len);
            raw.positions.reserve_exact(n);
            normals.reserve_exact(if has_normals { n } else { 0 });
            uvs.reserve_exact(if uv_keys.is_some() { n } else { 0 });
        } else if kind == "face" {
            raw.reserve_polygons(def.count.min(file_len));
        }
        for i in 0..def.count {
            let element = match header.encoding {
                Encoding::Ascii => {
                    line.clear();
                    let read = std::io::BufRead::read_line(reader.get_mut(), &mut line)
                        .map_err(|e| e.to_string())?;
                    if read == 0 {
                        return Err(format!(
                            "invalid PLY: unexpected end of file in element \"{kind}\" {i} of {}",
                            def.count
                        ));
                    }
                    parser.read_ascii_element(&line, def)
                }
                Encoding::BinaryLittleEndian => {
                    parser.read_little_endian_element(reader.get_mut(), def)
                }
                Encoding::BinaryBigEndian => parser.read_big_endian_element(reader.get_mut(), def),
            }
            .map_err(|e| {
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    // The binary readers' own words ("failed to fill whole buffer") hide it.
                    format!(
                        "invalid PLY: unexpected end of file in element \"{kind}\" {i} of {} \
                         (truncated file?)",
                        def.count
                    )
                } else {
                    format!("invalid PLY: element \"{kind}\" {i}: {e}")
                }
            })?;
            if kind == "vertex" {
                let v = &element;
                let get =
                    |k: &str| scalar(v, k).ok_or_else(|| format!("vertex without numeric \"{k}\""));
                read_attributes(v, &vertex_sources, &mut vertex_attributes)?;
                raw.positions
                    .push(Vec3::new(get("x")?, get("y")?, get("z")?));
                if has_normals {
                    normals.push(Vec3::new(get("nx")?, get("ny")?, get("nz")?));
                }
                if let Some((ku, kv)) = uv_keys {
                    uvs.push(Vec2::new(get(ku)?, get(kv)?));
                }
            } else if kind == "face" {
                let f = &element;
                let list = f
                    .get("vertex_indices")
                    .or_else(|| f.get("vertex_index"))
                    .ok_or("face without \"vertex_indices\"")?;
                idx.clear();
                match list {
                    Property::ListChar(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListUChar(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListShort(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListUShort(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListInt(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListUInt(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    _ => return Err("face indices are not an integer list".into()),
                }
                if idx.len() < 3 {
                    continue;
                }
                read_attributes(f, &face_sources, &mut face_attributes)?;
                if let Some(bad) = idx.iter().find(|&&i| i < 0 || i > i64::from(u32::MAX)) {
                    return Err(format!("invalid vertex index {bad}"));
                }
                raw.push_polygon(idx.iter().map(|&i| i as u32));
            }
        }
    }
    if has_normals {
        raw.normals = Some(normals);
    }
    if uv_keys.is_some() {
        raw.uvs = Some(uvs);
    }
    raw.attributes = vertex_attributes;
    raw.attributes.extend(face_attributes);
    let mut names = std::collections::HashSet::new();
    if let Some(a) = raw.attributes.iter().find(|a| !names.insert(&a.name)) {
        // Mitsuba: "add_attribute(): attribute … already exists".
        return Err(format!(
            "two property groups both make attribute \"{}\"",
            a.name
        ));
    }
    Ok(raw)
}

/// Empty attributes for the groups `sources` found in a PLY element.
fn new_attributes(sources: &[AttributeSource]) -> Vec<RawAttribute> {
    sources
        .iter()
        .map(|s| RawAttribute {
            name: s.name.clone(),
            channels: s.properties.len(),
            values: Vec::new(),
        })
        .collect()
}

/// Appends one PLY element's values of each attribute (converted as Mitsuba stores them).
fn read_attributes(
    e: &ply_rs_bw::ply::DefaultElement,
    sources: &[AttributeSource],
    out: &mut [RawAttribute],
) -> Result<(), String> {
    for (s, a) in sources.iter().zip(out) {
        for k in &s.properties {
            let v = e
                .get(k)
                .and_then(attribute_value)
                .ok_or_else(|| format!("attribute \"{}\": no numeric property \"{k}\"", s.name))?;
            a.values.push(v);
        }
    }
    Ok(())
}
