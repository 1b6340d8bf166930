//! Canonical EXR headers: sorts the header attributes of a single-part EXR by name, in place.
//!
//! Why: the `exr` crate writes custom attributes in `HashMap` order, which differs between
//! processes, so two runs that render identical pixels would write different bytes when a
//! file carries more than one custom attribute (bundles carry two). Sorting the attribute
//! records keeps the header's length, so the offset table and every chunk stay valid; readers
//! do not depend on attribute order.

use anyhow::{bail, Result};

/// Sorts the attributes of a single-part EXR header by name. Multi-part files are an error.
pub fn sort_header_attributes(bytes: &mut [u8]) -> Result<()> {
    if bytes.len() < 8 || bytes[..4] != [0x76, 0x2f, 0x31, 0x01] {
        bail!("not an OpenEXR file");
    }
    let flags = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
    if flags & 0x1000 != 0 {
        bail!("multi-part EXR headers are not canonicalised");
    }
    // Attribute records: name\0 type\0 size:i32 value[size]; the header ends with a \0.
    let mut records: Vec<(Vec<u8>, std::ops::Range<usize>)> = Vec::new();
    let mut at = 8;
    let start = at;
    loop {
        let Some(&first) = bytes.get(at) else {
            bail!("truncated EXR header");
        };
        if first == 0 {
            break;
        }
        let begin = at;
        let name_end = find_nul(bytes, at)?;
        let type_end = find_nul(bytes, name_end + 1)?;
        let size_at = type_end + 1;
        let Some(size) = bytes.get(size_at..size_at + 4) else {
            bail!("truncated EXR header");
        };
        let size = i32::from_le_bytes([size[0], size[1], size[2], size[3]]);
        if size < 0 {
            bail!("negative attribute size in EXR header");
        }
        let end = size_at + 4 + size as usize;
        if end > bytes.len() {
            bail!("truncated EXR header");
        }
        records.push((bytes[begin..name_end].to_vec(), begin..end));
        at = end;
    }
    let header = bytes[start..at].to_vec();
    records.sort_by(|a, b| a.0.cmp(&b.0));
    let mut out = Vec::with_capacity(header.len());
    for (_, range) in &records {
        out.extend_from_slice(&header[range.start - start..range.end - start]);
    }
    bytes[start..at].copy_from_slice(&out);
    Ok(())
}

/// Index of the next NUL at or after `from`.
fn find_nul(bytes: &[u8], from: usize) -> Result<usize> {
    match bytes
        .get(from..)
        .and_then(|s| s.iter().position(|&b| b == 0))
    {
        Some(k) => Ok(from + k),
        None => bail!("truncated EXR header"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal header with attributes `b`, `a` (not a real image; only the header matters).
    fn header(names: &[&str]) -> Vec<u8> {
        let mut v = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
        for n in names {
            v.extend_from_slice(n.as_bytes());
            v.push(0);
            v.extend_from_slice(b"string\0");
            v.extend_from_slice(&3i32.to_le_bytes());
            v.extend_from_slice(format!("<{n}>").as_bytes()[..3].as_ref());
        }
        v.push(0);
        v.extend_from_slice(b"PAYLOAD");
        v
    }

    #[test]
    fn sorts_records_and_keeps_payload() {
        let mut a = header(&["zeta", "alpha", "mid"]);
        let b = header(&["alpha", "mid", "zeta"]);
        assert_ne!(a, b);
        sort_header_attributes(&mut a).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn rejects_truncated_headers() {
        let h = header(&["b", "a"]);
        let mut cut = h[..14].to_vec();
        assert!(sort_header_attributes(&mut cut).is_err());
        assert!(sort_header_attributes(&mut b"nope".to_vec()).is_err());
    }
}
