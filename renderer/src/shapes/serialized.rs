//! Mitsuba's `serialized` mesh files for `<shape type="serialized">`: one mesh of a file that
//! holds several, read into a [`RawMesh`].

use super::mesh_file::RawMesh;
use glam::{Vec2, Vec3};
use std::path::Path;

/// Reads mesh `index` of a Mitsuba `.serialized` file: little-endian; per mesh a header
/// (`0x041C`, version 3 or 4) and a zlib stream holding flags, (v4) a name, vertex and triangle
/// counts, positions, optional normals (flag 0x0001), uvs (0x0002) and colours (0x0008, skipped)
/// in f32 (0x1000) or f64 (0x2000), then triangles (u32 indices; meshes past 2³² vertices are
/// refused); the
/// file ends with each mesh's offset (u64 in v4, u32 in v3) and the mesh count (u32). The
/// file's face-normal flag (0x0010) is ignored, as Mitsuba 3 does: the `face_normals`
/// parameter decides.
pub(crate) fn load_serialized(path: &Path, index: usize) -> Result<RawMesh, String> {
    use std::io::Read;
    let data = std::fs::read(path).map_err(|e| e.to_string())?;
    let u16_at = |at: usize| {
        data.get(at..at + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    };
    if data.len() < 8 || u16_at(0) != Some(0x041C) {
        return Err("not a Mitsuba serialized mesh file (no 0x041C header)".into());
    }
    let version = u16_at(2).unwrap_or(0);
    if version != 3 && version != 4 {
        return Err(format!(
            "serialized format version {version} (3 or 4 are supported)"
        ));
    }
    let n = data.len();
    let count = u32::from_le_bytes(data[n - 4..].try_into().expect("4 bytes")) as usize;
    if index >= count {
        return Err(format!(
            "shape_index {index}, but the file holds {count} mesh(es)"
        ));
    }
    let entry = if version == 4 { 8 } else { 4 };
    let table = n
        .checked_sub(4 + entry * count)
        .ok_or("truncated offset table")?;
    let at = table + entry * index;
    let offset = if version == 4 {
        u64::from_le_bytes(data[at..at + 8].try_into().expect("8 bytes")) as usize
    } else {
        u32::from_le_bytes(data[at..at + 4].try_into().expect("4 bytes")) as usize
    };
    if offset + 4 > table || u16_at(offset) != Some(0x041C) {
        return Err(format!("mesh {index}: bad offset {offset}"));
    }
    let mut body = Vec::new();
    flate2::read::ZlibDecoder::new(&data[offset + 4..table])
        .read_to_end(&mut body)
        .map_err(|e| format!("mesh {index}: corrupt zlib stream: {e}"))?;
    let mut cursor = 0usize;
    let mut take = |len: usize| -> Result<&[u8], String> {
        let bytes = body
            .get(cursor..cursor + len)
            .ok_or_else(|| format!("mesh {index}: truncated data"))?;
        cursor += len;
        Ok(bytes)
    };
    let flags = u32::from_le_bytes(take(4)?.try_into().expect("4 bytes"));
    if version == 4 {
        while take(1)?[0] != 0 {} // the mesh name
    }
    let vertices = u64::from_le_bytes(take(8)?.try_into().expect("8 bytes")) as usize;
    let triangles = u64::from_le_bytes(take(8)?.try_into().expect("8 bytes")) as usize;
    let double = flags & 0x2000 != 0;
    let mut reals = |k: usize| -> Result<Vec<f32>, String> {
        let width = if double { 8 } else { 4 };
        let bytes = take(k.checked_mul(width).ok_or("vertex count overflows")?)?;
        Ok(bytes
            .chunks_exact(width)
            .map(|c| {
                if double {
                    f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32
                } else {
                    f32::from_le_bytes(c.try_into().expect("4 bytes"))
                }
            })
            .collect())
    };
    let triples = |v: Vec<f32>| v.chunks_exact(3).map(Vec3::from_slice).collect::<Vec<_>>();
    let positions = triples(reals(3 * vertices)?);
    let normals = if flags & 0x0001 != 0 {
        Some(triples(reals(3 * vertices)?))
    } else {
        None
    };
    let uvs = if flags & 0x0002 != 0 {
        Some(
            reals(2 * vertices)?
                .chunks_exact(2)
                .map(Vec2::from_slice)
                .collect(),
        )
    } else {
        None
    };
    if flags & 0x0008 != 0 {
        reals(3 * vertices)?; // vertex colours: not used
    }
    if vertices > u32::MAX as usize {
        return Err(format!(
            "mesh {index}: {vertices} vertices (at most 2³² are supported)"
        ));
    }
    let indices: Vec<u32> = take(
        triangles
            .checked_mul(12)
            .ok_or("triangle count overflows")?,
    )?
    .chunks_exact(4)
    .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
    .collect();
    let polygon_ends = (1..=triangles).map(|t| 3 * t).collect();
    Ok(RawMesh {
        positions,
        normals,
        uvs,
        corners: indices,
        polygon_ends,
        attributes: Vec::new(),
    })
}
