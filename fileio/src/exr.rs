//! Float32 OpenEXR files of named channels, the one EXR writer and reader of the toolkit: bundles (many
//! layers and a metadata attribute), references and reconstructions (`R`, `G`, `B`), the
//! renderer's images and AOVs. Every file is single-part, ZIP-compressed in increasing line
//! order, its channels sorted by name as OpenEXR requires, written atomically: its bytes are a
//! function of the pixels alone (the `exr` crate's default — tiles in unspecified order — stores
//! blocks in the order its compression threads finish).

use std::collections::HashMap;
use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Image, Layer, LayerAttributes,
    ReadChannels, ReadLayers, Text, WritableImage,
};

use crate::atomic::write_bytes;

/// Channel names of an RGB image.
pub const RGB: [&str; 3] = ["R", "G", "B"];

/// Why an EXR could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ExrError {
    /// A channel name OpenEXR cannot store.
    #[error("channel name {name:?} {why}")]
    ChannelName {
        /// The name.
        name: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// A channel's plane does not hold `width`·`height` values.
    #[error("channel {name:?} holds {len} values, a {width}x{height} image needs {}", width * height)]
    Size {
        /// The channel.
        name: String,
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Values in the plane.
        len: usize,
    },
    /// Writing the file failed.
    #[error("{0}")]
    Io(std::io::Error),
    /// The encoder failed.
    #[error("{0}")]
    Exr(exr::error::Error),
    /// The written header could not be put in canonical order (a malformed file).
    #[error("{0}")]
    Header(String),
}

impl From<exr::error::Error> for ExrError {
    fn from(e: exr::error::Error) -> Self {
        match e {
            exr::error::Error::Io(e) => Self::Io(e),
            e => Self::Exr(e),
        }
    }
}

/// What keeps OpenEXR from storing `name` as a channel name, if anything: an empty name, one
/// longer than its 255 bytes, or one with a NUL (the format's strings end at NUL).
pub fn channel_name_problem(name: &str) -> Option<&'static str> {
    match name.len() {
        0 => Some("is empty"),
        256.. => Some("is longer than OpenEXR's 255 bytes"),
        _ if name.contains('\0') => Some("holds a NUL character"),
        _ => None,
    }
}

/// Writes `channels` (`(name, plane)`, each plane `width`·`height` values, rows top to bottom)
/// to `path`, with `attributes` as text attributes of the header (their bytes as they are:
/// UTF-8 passes through), atomically.
pub fn write_channels(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, Vec<f32>)>,
    attributes: &[(&str, &[u8])],
) -> Result<(), ExrError> {
    for (name, _) in &channels {
        if let Some(why) = channel_name_problem(name) {
            return Err(ExrError::ChannelName {
                name: name.clone(),
                why,
            });
        }
    }
    if let Some((name, plane)) = channels.iter().find(|(_, p)| p.len() != width * height) {
        return Err(ExrError::Size {
            name: name.clone(),
            width,
            height,
            len: plane.len(),
        });
    }
    let list = channels
        .into_iter()
        // UTF-8 bytes as they are, as OpenEXR stores names (exr's `Text::from` panics on
        // characters beyond Latin-1).
        .map(|(name, plane)| {
            AnyChannel::new(
                Text::from_slice_unchecked(name.as_bytes()),
                FlatSamples::F32(plane),
            )
        })
        .collect();
    let other: HashMap<Text, AttributeValue> = attributes
        .iter()
        .map(|(name, value)| {
            (
                Text::from_slice_unchecked(name.as_bytes()),
                AttributeValue::Text(Text::from_slice_unchecked(value)),
            )
        })
        .collect();
    let layer = Layer::new(
        (width, height),
        LayerAttributes {
            other,
            ..LayerAttributes::default()
        },
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(ExrError::from)?;
    let mut bytes = bytes.into_inner();
    // The `exr` crate writes custom attributes in `HashMap` order, which differs between
    // processes: with more than one, the same pixels would give different bytes.
    if attributes.len() > 1 {
        sort_header_attributes(&mut bytes).map_err(ExrError::Header)?;
    }
    write_bytes(path, &bytes).map_err(ExrError::Io)
}

/// Sorts the attribute records of a single-part EXR header by name, in place (multi-part files
/// are an error). The header keeps its length, so the offset table and every chunk stay valid;
/// readers do not depend on attribute order.
fn sort_header_attributes(bytes: &mut [u8]) -> Result<(), String> {
    if bytes.len() < 8 || bytes[..4] != [0x76, 0x2f, 0x31, 0x01] {
        return Err("not an OpenEXR file".into());
    }
    let flags = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
    if flags & 0x1000 != 0 {
        return Err("multi-part EXR headers are not canonicalised".into());
    }
    // Attribute records: name\0 type\0 size:i32 value[size]; the header ends with a \0.
    let mut records: Vec<(Vec<u8>, std::ops::Range<usize>)> = Vec::new();
    let mut at = 8;
    let start = at;
    loop {
        let Some(&first) = bytes.get(at) else {
            return Err("truncated EXR header".into());
        };
        if first == 0 {
            break;
        }
        let begin = at;
        let name_end = find_nul(bytes, at)?;
        let type_end = find_nul(bytes, name_end + 1)?;
        let size_at = type_end + 1;
        let Some(size) = bytes.get(size_at..size_at + 4) else {
            return Err("truncated EXR header".into());
        };
        let size = i32::from_le_bytes([size[0], size[1], size[2], size[3]]);
        if size < 0 {
            return Err("negative attribute size in EXR header".into());
        }
        let end = size_at + 4 + size as usize;
        if end > bytes.len() {
            return Err("truncated EXR header".into());
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
fn find_nul(bytes: &[u8], from: usize) -> Result<usize, String> {
    match bytes
        .get(from..)
        .and_then(|s| s.iter().position(|&b| b == 0))
    {
        Some(k) => Ok(from + k),
        None => Err("truncated EXR header".into()),
    }
}

/// Writes an RGB image given as three planes (`R`, `G`, `B`) to `path`, atomically.
pub fn write_rgb(
    path: &Path,
    width: usize,
    height: usize,
    planes: [Vec<f32>; 3],
) -> Result<(), ExrError> {
    let channels = RGB.iter().map(|c| (*c).to_owned()).zip(planes).collect();
    write_channels(path, width, height, channels, &[])
}

/// An EXR's first layer as read: resolution, channel planes by full name (values as f32), and
/// the header's other attributes.
pub struct ExrChannels {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Each channel's samples, rows top to bottom, by full name (`z3.G`, `R`).
    pub planes: HashMap<String, Vec<f32>>,
    /// The header's attributes beyond OpenEXR's standard ones (image and layer).
    pub attributes: HashMap<Text, AttributeValue>,
}

/// Why an EXR could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ExrReadError {
    /// The file could not be opened or read.
    #[error("{0}")]
    Io(std::io::Error),
    /// The EXR library rejected the file (truncated, corrupt, not an EXR).
    #[error("{0}")]
    Exr(exr::error::Error),
    /// The data window is one the readers cannot take or the file cannot hold (the reason
    /// names the value).
    #[error("dataWindow: {0}")]
    DataWindow(String),
}

/// Reads the first layer of the EXR `path` with all its channels and attributes. The headers
/// are checked before any pixel is decoded ([`check_header`]): a corrupt file is an error, never
/// a failed allocation.
pub fn read_channels(path: &Path) -> Result<ExrChannels, ExrReadError> {
    check_header(path)?;
    let file = std::fs::File::open(path).map_err(ExrReadError::Io)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .pedantic()
        .from_unbuffered(file)
        .map_err(ExrReadError::Exr)?;
    let layer = image.layer_data;
    let mut planes = HashMap::new();
    for channel in layer.channel_data.list {
        let name = String::from_utf8_lossy(channel.name.as_slice()).into_owned();
        planes.insert(name, channel.sample_data.values_as_f32().collect());
    }
    let mut attributes = image.attributes.other;
    attributes.extend(layer.attributes.other);
    Ok(ExrChannels {
        width: layer.size.0,
        height: layer.size.1,
        planes,
        attributes,
    })
}

/// Decoded bytes a file may claim per byte it holds. Above the best ratio of any lossless EXR
/// compression (deflate, as in ZIP: 1032:1), so no valid file is refused, while a corrupt
/// header that claims gigabytes for a small file is refused before anything is allocated.
const MAX_EXPANSION: u64 = 2048;

/// Checks an EXR's headers before its pixels are decoded: each layer's data window must start
/// at (0, 0) (the readers here index pixels from the window's corner) and its decoded size must
/// be one the file's length can hold. The EXR library allocates what a header claims, so a
/// single corrupt number would otherwise end the process on a failed allocation. The first
/// header's raw window is checked before the library parses it, so that every corrupt window is
/// an error naming `dataWindow` and its value.
fn check_header(path: &Path) -> Result<(), ExrReadError> {
    let io = ExrReadError::Io;
    let file_len = std::fs::metadata(path).map_err(io)?.len();
    // The raw window first: the EXR library refuses some corrupt windows itself (coordinates
    // beyond ±(2³⁰ − 1), a window its chunk count does not match) with messages that do not
    // name the attribute.
    let mut prefix = Vec::new();
    {
        use std::io::Read;
        let file = std::fs::File::open(path).map_err(io)?;
        file.take(RAW_HEADER_BYTES)
            .read_to_end(&mut prefix)
            .map_err(io)?;
    }
    if let Some((window, channels)) = raw_window_and_channels(&prefix) {
        let [x0, y0, x1, y1] = window.map(i64::from);
        check_window(
            file_len,
            (x0, y0),
            (x1 - x0 + 1, y1 - y0 + 1),
            channels as u64,
        )?;
    }
    let meta = exr::meta::MetaData::read_from_file(path, true).map_err(ExrReadError::Exr)?;
    for header in meta.headers.iter() {
        let position = header.own_attributes.layer_position;
        check_window(
            file_len,
            (i64::from(position.0), i64::from(position.1)),
            (header.layer_size.0 as i64, header.layer_size.1 as i64),
            header.channels.list.len() as u64,
        )?;
    }
    Ok(())
}

/// Bytes at the start of a file searched for the first header's raw attributes (a bundle's
/// header, its JSON metadata included, is a few kilobytes; a longer header is left to the EXR
/// library). Kept small: every bundle read pays for it, on top of the library's own read.
const RAW_HEADER_BYTES: u64 = 64 << 10;

/// Refuses a data window (corner `position`, `size` in pixels, `channels` channels) that does
/// not start at (0, 0), is empty, or holds more float32 samples than a file of `file_len` bytes
/// can decode to: an error with the offending value.
fn check_window(
    file_len: u64,
    position: (i64, i64),
    size: (i64, i64),
    channels: u64,
) -> Result<(), ExrReadError> {
    let bad = ExrReadError::DataWindow;
    if position != (0, 0) {
        return Err(bad(format!(
            "starts at ({}, {}); expected (0, 0)",
            position.0, position.1
        )));
    }
    let (width, height) = size;
    if width <= 0 || height <= 0 {
        return Err(bad(format!("{width}x{height} pixels: empty or inverted")));
    }
    let bytes = (width as u64)
        .saturating_mul(height as u64)
        .saturating_mul(channels)
        .saturating_mul(4);
    if bytes
        > file_len
            .saturating_mul(MAX_EXPANSION)
            .saturating_add(1 << 20)
    {
        return Err(bad(format!(
            "{width}x{height} pixels of {channels} channels cannot come from a file of \
             {file_len} bytes (corrupt header)"
        )));
    }
    Ok(())
}

/// The number of entries of a raw `chlist` attribute value: each a name, then 16 bytes (type,
/// linear, reserved, sampling); an empty name ends the list.
fn raw_channel_count(value: &[u8]) -> Option<usize> {
    let (mut count, mut k) = (0, 0);
    while *value.get(k)? != 0 {
        k += value[k..].iter().position(|&b| b == 0)? + 1 + 16;
        count += 1;
    }
    Some(count)
}

/// The first header's `dataWindow` (xMin, yMin, xMax, yMax) and number of channels, read from
/// the raw attributes at the start of an EXR (`bytes`: magic number, version, then attributes
/// as name, type, size, value); `None` where the header is not laid out so (the EXR library
/// then reports it).
fn raw_window_and_channels(bytes: &[u8]) -> Option<([i32; 4], usize)> {
    let c_string = |at: usize| -> Option<(&[u8], usize)> {
        let len = bytes.get(at..)?.iter().position(|&b| b == 0)?;
        Some((&bytes[at..at + len], at + len + 1))
    };
    let i32_at = |at: usize| -> Option<i32> {
        Some(i32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
    };
    let (mut window, mut channels) = (None, None);
    let mut at = 8;
    loop {
        let (name, next) = c_string(at)?;
        if name.is_empty() {
            break;
        }
        let (kind, next) = c_string(next)?;
        let size = usize::try_from(i32_at(next)?).ok()?;
        let value_at = next + 4;
        let end = value_at.checked_add(size)?;
        let value = bytes.get(value_at..end)?;
        match (name, kind) {
            (b"dataWindow", b"box2i") if size == 16 => {
                let n = |k: usize| i32_at(value_at + 4 * k);
                window = Some([n(0)?, n(1)?, n(2)?, n(3)?]);
            }
            (b"channels", b"chlist") => channels = raw_channel_count(value),
            _ => {}
        }
        at = end;
    }
    Some((window?, channels.unwrap_or(1)))
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

    #[test]
    fn channels_and_attributes_round_trip_and_bad_names_are_refused() {
        let dir = std::env::temp_dir().join(format!("fileio-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (3, 2);
        let plane = |salt: f32| {
            (0..w * h)
                .map(|i| salt + i as f32 * 0.5)
                .collect::<Vec<_>>()
        };
        let path = dir.join("a.exr");
        write_channels(
            &path,
            w,
            h,
            vec![("z.Y".into(), plane(10.0)), ("a ✓".into(), plane(20.0))],
            &[("meta", "ü {}".as_bytes()), ("format", b"v1")],
        )
        .unwrap();
        let image = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_file(&path)
            .unwrap();
        let layer = &image.layer_data[0];
        let names: Vec<String> = layer
            .channel_data
            .list
            .iter()
            .map(|c| String::from_utf8(c.name.bytes().to_vec()).unwrap())
            .collect();
        assert_eq!(names, ["a ✓", "z.Y"]);
        let FlatSamples::F32(values) = &layer.channel_data.list[1].sample_data else {
            panic!("not f32");
        };
        assert_eq!(values, &plane(10.0));
        let meta = &layer.attributes.other[&Text::from("meta")];
        assert_eq!(
            meta,
            &AttributeValue::Text(Text::from_slice_unchecked("ü {}".as_bytes()))
        );

        // The same pixels give the same bytes.
        let again = dir.join("b.exr");
        write_rgb(&again, w, h, [plane(1.0), plane(2.0), plane(3.0)]).unwrap();
        let first = std::fs::read(&again).unwrap();
        write_rgb(&again, w, h, [plane(1.0), plane(2.0), plane(3.0)]).unwrap();
        assert_eq!(std::fs::read(&again).unwrap(), first);

        for (name, want) in [("", "is empty"), ("a\0b", "NUL")] {
            let err = write_channels(
                &dir.join("c.exr"),
                w,
                h,
                vec![(name.into(), plane(0.0))],
                &[],
            )
            .unwrap_err();
            assert!(err.to_string().contains(want), "{err}");
        }
        let err = write_rgb(
            &dir.join("c.exr"),
            w,
            h,
            [plane(0.0), vec![1.0], plane(0.0)],
        )
        .unwrap_err();
        assert!(err.to_string().contains("holds 1 values"), "{err}");
        assert!(!dir.join("c.exr").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The raw header scan reads the data window and channel count the writer wrote, for
    /// files of a bundle's 27 and 32 channels with attributes and for plain RGB images.
    #[test]
    fn raw_header_scan_finds_the_written_window_and_channels() {
        let dir = std::env::temp_dir().join(format!("fileio-raw-header-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for channels in [27, 32] {
            let path = dir.join(format!("c{channels}.exr"));
            let list = (0..channels)
                .map(|c| (format!("layer{}.{c}", c / 3), vec![c as f32; 35]))
                .collect();
            let attributes = [("meta", &b"{\"a\": 1}"[..]), ("format", &b"v1"[..])];
            write_channels(&path, 7, 5, list, &attributes).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(
                raw_window_and_channels(&bytes),
                Some(([0, 0, 6, 4], channels)),
                "{}",
                path.display()
            );
        }
        let path = dir.join("rgb.exr");
        write_rgb(&path, 9, 2, [vec![0.0; 18], vec![0.0; 18], vec![0.0; 18]]).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            raw_window_and_channels(&bytes),
            Some(([0, 0, 8, 1], 3)),
            "{}",
            path.display()
        );
        // Not an EXR header: nothing found, the EXR library reports it.
        assert_eq!(raw_window_and_channels(b"P6\n16 16\n255\n"), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
