//! Wavefront OBJ meshes for `<shape type="obj">`: read with `tobj`, and, when `tobj` rejects a
//! file, the line it stopped at. `tobj` reports only the kind of error ("face parse error"), so
//! a failed file is read a second time by [`locate_error`], which follows `tobj`'s own rules
//! line by line; the success path streams the file once and pays nothing for this.

use super::mesh_file::RawMesh;
use glam::{Vec2, Vec3};
use std::io::BufRead;
use std::path::Path;

/// Reads a Wavefront OBJ (all objects/groups merged into one mesh, as Mitsuba).
pub(crate) fn load_obj(path: &Path) -> Result<RawMesh, String> {
    if !path.is_file() {
        return Err("file not found".into());
    }
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let open = || std::fs::File::open(path).map(std::io::BufReader::new);
    // Materials are irrelevant (the XML assigns the BSDF): never fail on a missing .mtl.
    let loaded = tobj::load_obj_buf(&mut open().map_err(|e| e.to_string())?, &options, |_| {
        Ok(Default::default())
    });
    let (models, _materials) = match loaded {
        Ok(loaded) => loaded,
        Err(e) => {
            // Where: a second read that follows tobj's rules (it reports no line itself).
            let line = open()
                .ok()
                .and_then(|mut reader| locate_error(&mut reader).ok().flatten());
            let quote = line.and_then(|n| quote_line(&mut open().ok()?, n));
            return Err(match (line, quote) {
                (Some(n), Some(text)) => format!("invalid OBJ: line {n}: {e}: `{text}`"),
                (Some(n), None) => format!("invalid OBJ: line {n}: {e}"),
                _ => format!("invalid OBJ: {e}"),
            });
        }
    };
    let mut raw = RawMesh::default();
    let all_normals = models.iter().all(|m| !m.mesh.normals.is_empty());
    let any_uvs = models.iter().any(|m| !m.mesh.texcoords.is_empty());
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let base = raw.positions.len() as u32;
        let count = m.positions.len() / 3;
        raw.positions.extend(
            m.positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        if all_normals {
            if m.normals.len() != m.positions.len() {
                return Err("normal count differs from vertex count".into());
            }
            normals.extend(
                m.normals
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2])),
            );
        }
        if any_uvs {
            if m.texcoords.is_empty() {
                uvs.extend(std::iter::repeat_n(Vec2::ZERO, count));
            } else if m.texcoords.len() / 2 == count {
                uvs.extend(m.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])));
            } else {
                return Err("texture coordinate count differs from vertex count".into());
            }
        }
        // Polygons: face_arities lists corner counts (empty = all triangles).
        let mut offset = 0usize;
        let arities: Vec<u32> = if m.face_arities.is_empty() {
            vec![3; m.indices.len() / 3]
        } else {
            m.face_arities.clone()
        };
        for a in arities {
            let end = offset + a as usize;
            let Some(corners) = m.indices.get(offset..end) else {
                return Err("inconsistent face data".into());
            };
            if a >= 3 {
                raw.push_polygon(corners.iter().map(|i| base + i));
            }
            offset = end;
        }
    }
    if all_normals && !models.is_empty() {
        raw.normals = Some(normals);
    }
    if any_uvs {
        raw.uvs = Some(uvs);
    }
    Ok(raw)
}

/// Line `number` (1-based) of a file, cut to 60 characters for an error message.
fn quote_line(reader: &mut impl BufRead, number: usize) -> Option<String> {
    let mut bytes = Vec::new();
    for _ in 0..number {
        bytes.clear();
        if reader.read_until(b'\n', &mut bytes).ok()? == 0 {
            return None;
        }
    }
    let text = String::from_utf8_lossy(&bytes);
    let text = text.trim();
    Some(match text.char_indices().nth(60) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_string(),
    })
}

/// What `tobj` resolves an absent index to (and, through wrapping, a relative index one before
/// the first element): the bounds check skips it for texture coordinates and normals and
/// rejects it for positions.
const MISSING: usize = usize::MAX;

/// Element counts read so far, as `tobj` keeps them (global over the file).
#[derive(Default)]
struct Counts {
    positions: usize,
    texcoords: usize,
    normals: usize,
    /// Vertex colour values (`v x y z r g b`); once any exists, every vertex a face uses needs
    /// its three.
    colours: usize,
}

/// The faces of the current object that `tobj` checks when the object ends, reduced to what
/// decides the first failure: per index kind, the faces that raised the largest index so far
/// (line, index). The bounds are only known when the object ends, and the first face to fail
/// against a bound is the first of these records at or above it.
#[derive(Default)]
struct PendingFaces {
    records: [Vec<(usize, usize)>; 3],
}

impl PendingFaces {
    /// Notes a polygon's largest index of each kind (`None`: that kind not given).
    fn add(&mut self, line: usize, reach: [Option<usize>; 3]) {
        for (records, index) in self.records.iter_mut().zip(reach) {
            if let Some(index) = index {
                if records.last().is_none_or(|&(_, top)| index > top) {
                    records.push((line, index));
                }
            }
        }
    }

    /// The line of the first face with an index past the element counts, as `tobj` checks them
    /// when the object ends (texture coordinates and normals only when the file has some).
    fn first_out_of_range(&self, counts: &Counts) -> Option<usize> {
        let position_bound = if counts.colours > 0 {
            counts.positions.min(counts.colours / 3)
        } else {
            counts.positions
        };
        let bounds = [
            Some(position_bound),
            (counts.texcoords > 0).then_some(counts.texcoords),
            (counts.normals > 0).then_some(counts.normals),
        ];
        self.records
            .iter()
            .zip(bounds)
            .filter_map(|(records, bound)| {
                let bound = bound?;
                records
                    .iter()
                    .find(|&&(_, i)| i >= bound)
                    .map(|&(line, _)| line)
            })
            .min()
    }
}

/// Finds the first line of an OBJ that `tobj` (with the options of [`load_obj`]) rejects, by
/// the same rules: `v` needs three numbers, then nothing, a non-zero `w`, or three colour values;
/// `vt` two numbers; `vn` three; every `f`/`l` corner `v`, `v/t`, `v//n` or `v/t/n` with integer
/// indices; `usemtl` a name; and, when an object ends (an `o`/`g` line after faces, or the end
/// of the file), every polygon's indices in range (points and lines are not checked: `load_obj`
/// has `tobj` ignore them). A line that is not UTF-8 is rejected too. `Ok(None)` when no line
/// breaks these rules.
fn locate_error(reader: &mut impl BufRead) -> std::io::Result<Option<usize>> {
    let mut counts = Counts::default();
    let mut pending = PendingFaces::default();
    // Whether the current object has faces of any arity (what makes an `o`/`g` line end it).
    let mut object_has_faces = false;
    let mut bytes = Vec::new();
    let mut number = 0usize;
    loop {
        bytes.clear();
        if reader.read_until(b'\n', &mut bytes)? == 0 {
            break;
        }
        number += 1;
        if bytes.last() == Some(&b'\n') {
            bytes.pop();
            if bytes.last() == Some(&b'\r') {
                bytes.pop();
            }
        }
        let Ok(line) = std::str::from_utf8(&bytes) else {
            return Ok(Some(number));
        };
        let mut words = line.split_whitespace();
        let valid = match words.next() {
            Some("v") => {
                let valid = numbers(&mut words, 3)
                    && match words.collect::<Vec<_>>().as_slice() {
                        [] => true,
                        [w] => w.parse::<f32>().is_ok_and(|w| w != 0.0),
                        [r, g, b] => {
                            // tobj keeps the colour values up to the first that is not a number.
                            counts.colours += [r, g, b]
                                .iter()
                                .take_while(|c| c.parse::<f32>().is_ok())
                                .count();
                            true
                        }
                        _ => false,
                    };
                counts.positions += 1;
                valid
            }
            Some("vt") => {
                counts.texcoords += 1;
                numbers(&mut words, 2)
            }
            Some("vn") => {
                counts.normals += 1;
                numbers(&mut words, 3)
            }
            Some("f") | Some("l") => {
                let mut reach: [Option<usize>; 3] = [None; 3];
                let mut corners = 0usize;
                let mut valid = true;
                for word in words {
                    let Some(indices) = corner(word, &counts) else {
                        valid = false;
                        break;
                    };
                    corners += 1;
                    for (kind, (slot, index)) in reach.iter_mut().zip(indices).enumerate() {
                        // An absent position is out of range; absent others are not checked.
                        if index != MISSING || kind == 0 {
                            *slot = Some(slot.map_or(index, |s| s.max(index)));
                        }
                    }
                }
                object_has_faces = true;
                if valid && corners >= 3 {
                    pending.add(number, reach);
                }
                valid
            }
            Some("o") | Some("g") => {
                if object_has_faces {
                    if let Some(bad) = pending.first_out_of_range(&counts) {
                        return Ok(Some(bad));
                    }
                    pending = PendingFaces::default();
                    object_has_faces = false;
                }
                true
            }
            Some("usemtl") => !line.split_once(' ').unwrap_or_default().1.trim().is_empty(),
            _ => true,
        };
        if !valid {
            return Ok(Some(number));
        }
    }
    Ok(pending.first_out_of_range(&counts))
}

/// Whether the next `n` words are all numbers (and there are `n` of them).
fn numbers<'a>(words: &mut impl Iterator<Item = &'a str>, n: usize) -> bool {
    let mut found = 0;
    for word in words.take(n) {
        if word.parse::<f32>().is_err() {
            return false;
        }
        found += 1;
    }
    found == n
}

/// A face corner `v`, `v/t`, `v//n` or `v/t/n` resolved to 0-based indices as `tobj` does
/// (`None`: not integers, or more than three).
fn corner(word: &str, counts: &Counts) -> Option<[usize; 3]> {
    let mut indices = [MISSING; 3];
    let sizes = [counts.positions, counts.texcoords, counts.normals];
    for (slot, part) in word.split('/').enumerate() {
        if part.is_empty() {
            continue;
        }
        let x: isize = part.parse().ok()?;
        let size = *sizes.get(slot)?;
        *indices.get_mut(slot)? = if x < 0 {
            (size as isize).wrapping_add(x) as usize
        } else {
            (x - 1) as usize
        };
    }
    Some(indices)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tobj_accepts(text: &str) -> bool {
        let options = tobj::LoadOptions {
            single_index: true,
            triangulate: false,
            ignore_points: true,
            ignore_lines: true,
        };
        tobj::load_obj_buf(&mut text.as_bytes(), &options, |_| Ok(Default::default())).is_ok()
    }

    fn locate(text: &str) -> Option<usize> {
        locate_error(&mut text.as_bytes()).unwrap()
    }

    const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

    #[test]
    fn each_kind_of_bad_line_is_found() {
        let cases: &[(&str, Option<usize>)] = &[
            ("f 1 2 3\n", None),
            ("vn 0 0 1\nf 1//1 2//1 3//1\n", None),
            ("v 1 2\n", Some(4)),
            ("v 1 2 x\n", Some(4)),
            ("v 1 2 3 0\n", Some(4)),
            ("v 1 2 3 4 5\n", Some(4)),
            ("v 1 2 3 4 5 6 7\n", Some(4)),
            ("vt 0.5\n", Some(4)),
            ("vn 0 0\n", Some(4)),
            ("f 1 2 x\n", Some(4)),
            ("f 1/2/3/4 2 3\n", Some(4)),
            ("f 1 2 4\n", Some(4)),
            ("f 1 2 -4\n", Some(4)),
            ("f 0 1 2\n", Some(4)),
            ("vt 0 0\nf 1/1 2/2 3/1\n", Some(5)),
            ("vn 0 0 1\nf 1//1 2//1 3//2\n", Some(5)),
            // Points and lines are skipped, so their indices are never checked.
            ("l 1 9\np 7\nf 1 2 3\n", None),
            ("usemtl\n", Some(4)),
            ("usemtl red\nf 1 2 3\n", None),
            // A face may name a vertex written after it, up to the end of its object.
            ("f 1 2 4\nv 1 1 0\n", None),
            ("f 1 2 4\ng next\nv 1 1 0\n", Some(4)),
            // Vertex colours, once present, are needed by every vertex a face uses.
            ("v 1 1 1 1 0 0\nf 1 2 4\n", Some(5)),
        ];
        for (tail, expected) in cases {
            let text = format!("{TRIANGLE}{tail}");
            assert_eq!(locate(&text), *expected, "{text:?}");
            assert_eq!(tobj_accepts(&text), expected.is_none(), "{text:?}");
        }
        let text = b"v 0 0 0\nv 1 \xff 0\n";
        assert_eq!(locate_error(&mut &text[..]).unwrap(), Some(2));
    }

    #[test]
    fn agrees_with_tobj_on_mutated_files() {
        // A small mesh with every element kind; each mutation replaces one token of one line.
        let base = "# test\nmtllib a.mtl\no one\nv 0 0 0\nv 1 0 0\nv 0 1 0 1\nv 1 1 0\n\
                    vt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nvn 0 0 1\nusemtl red\n\
                    f 1/1/1 2/2/1 3/3/2\nf 2//1 4//2 3//1\ng two\nv 2 2 2\nf -1 -2 -3 1\nl 1 2\n";
        assert!(tobj_accepts(base));
        assert_eq!(locate(base), None);
        let replacements = [
            "x", "0", "-9", "9", "1/9", "1//9", "1/1/1/1", "", "1e3", "//", "-1/-1/-1", "1 2",
        ];
        let lines: Vec<&str> = base.lines().collect();
        let mut checked = 0;
        for (li, line) in lines.iter().enumerate() {
            let words: Vec<&str> = line.split(' ').collect();
            for wi in 0..words.len() {
                for r in replacements {
                    let mut w = words.clone();
                    w[wi] = r;
                    let mut mutated: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
                    mutated[li] = w.join(" ");
                    let text = mutated.join("\n") + "\n";
                    let found = locate(&text);
                    assert_eq!(found.is_none(), tobj_accepts(&text), "{text}");
                    if let Some(n) = found {
                        // tobj stops at that line: everything before it is fine (this mesh
                        // refers to no vertex before it is written, so a prefix stands alone).
                        let before: String =
                            text.lines().take(n - 1).map(|l| format!("{l}\n")).collect();
                        let through: String =
                            text.lines().take(n).map(|l| format!("{l}\n")).collect();
                        assert!(tobj_accepts(&before), "{text}\nline {n}");
                        assert!(!tobj_accepts(&through), "{text}\nline {n}");
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 50, "only {checked} rejected mutations");
    }
}
