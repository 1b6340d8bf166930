//! Reading and writing plain RGB images: PNG (sRGB-encoded) and OpenEXR (linear float) both
//! ways; JPEG, TGA, BMP (sRGB-encoded), Radiance HDR and PFM (linear) read only, for textures.
//!
//! Everything here works in linear sRGB: encoded images are decoded through the sRGB transfer
//! curve (unless read "raw", as Mitsuba's `bitmap` with `raw=true`), HDR and EXR are taken as
//! they are.
//! Writers are atomic: the image goes to a temporary file next to the target, which is then
//! renamed over it, so a reader never sees a half-written file.

use crate::spectrum::Rgb;
use std::path::{Path, PathBuf};

/// An image file could not be read or written; every variant names the file.
// The cause is part of each message, not a `source`: error chains printed with `{:#}` would
// otherwise repeat it.
#[derive(Debug, thiserror::Error)]
pub enum ImageIoError {
    /// The file could not be opened, created or renamed.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The OpenEXR decoder or encoder failed (corrupt file, no R/G/B channels, …).
    #[error("{path}: OpenEXR: {error}")]
    Exr {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: exr::error::Error,
    },
    /// An OpenEXR file without the R, G and B channels of its first layer, or with a data
    /// window the reader cannot take.
    #[error("{path}: OpenEXR: {why}")]
    ExrLayout {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// The PNG decoder or encoder failed.
    #[error("{path}: PNG: {error}")]
    Png {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: image::ImageError,
    },
    /// Decoding an image other than OpenEXR failed (corrupt or truncated file, …).
    #[error("{path}: {format}: {error}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The format its first bytes name ("JPEG", "Radiance HDR", …).
        format: &'static str,
        /// The underlying error.
        error: image::ImageError,
    },
    /// A portable float map is malformed.
    #[error("{path}: PFM: {why}")]
    Pfm {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// The file is in none of the formats this module reads.
    #[error(
        "{path}: unsupported image format (not a PNG, JPEG, TGA, BMP, PPM, Radiance HDR, PFM or OpenEXR file)"
    )]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The pixel buffer handed to a writer does not match width × height.
    #[error("{path}: {len} pixels given for a {width}x{height} image")]
    SizeMismatch {
        /// The file.
        path: PathBuf,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
        /// Number of pixels given.
        len: usize,
    },
    /// A channel name OpenEXR cannot store (empty, longer than 255 bytes, or with a NUL).
    #[error("{path}: channel name {name:?} {why}")]
    ChannelName {
        /// The file.
        path: PathBuf,
        /// The name.
        name: String,
        /// What is wrong.
        why: &'static str,
    },
}

/// A decoded image: width, height and row-major linear-RGB pixels (row 0 is the top row).
pub type RgbImage = (u32, u32, Vec<Rgb>);

/// The file formats this module knows, recognised as Mitsuba's `bitmap` does by the first
/// bytes of the file, and by the name's extension only where those say nothing (TGA files
/// without a version-2 footer, damaged files).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    /// 8- or 16-bit sRGB-encoded images: PNG (also written), JPEG, TGA, BMP, binary PPM —
    /// named, and decoded by the `image` crate.
    Encoded(&'static str, image::ImageFormat),
    /// Radiance RGBE (`.hdr`): linear.
    Hdr,
    /// Portable float map (`.pfm`, colour `PF` or grey `Pf`): linear.
    Pfm,
    /// OpenEXR: linear (also written).
    Exr,
}

/// The format of the image in `path`: by its signature (as Mitsuba's
/// `Bitmap::detect_file_format`), else by the TGA footer, else by the name's extension.
fn format_of(path: &Path) -> Result<Format, ImageIoError> {
    use std::io::{Read, Seek, SeekFrom};
    let io_err = |error| ImageIoError::Io {
        path: path.to_owned(),
        error,
    };
    let mut file = std::fs::File::open(path).map_err(io_err)?;
    let mut start = Vec::with_capacity(8);
    (&mut file)
        .take(8)
        .read_to_end(&mut start)
        .map_err(io_err)?;
    let sniffed = match start.as_slice() {
        [b'B', b'M', ..] => Some(Format::Encoded("BMP", image::ImageFormat::Bmp)),
        [b'#', b'?', ..] => Some(Format::Hdr),
        [b'P', b'F' | b'f', ..] => Some(Format::Pfm),
        [b'P', b'6', ..] => Some(Format::Encoded("PPM", image::ImageFormat::Pnm)),
        [0xFF, 0xD8, ..] => Some(Format::Encoded("JPEG", image::ImageFormat::Jpeg)),
        [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A] => {
            Some(Format::Encoded("PNG", image::ImageFormat::Png))
        }
        [0x76, 0x2F, 0x31, 0x01, ..] => Some(Format::Exr),
        _ => None,
    };
    if let Some(format) = sniffed {
        return Ok(format);
    }
    // A TGA (version 2) ends with an 18-byte footer; version 1 files are known by name only.
    let mut footer = [0u8; 18];
    if file.seek(SeekFrom::End(-18)).is_ok()
        && file.read_exact(&mut footer).is_ok()
        && footer.starts_with(b"TRUEVISION-XFILE.")
        && footer[17] == 0
    {
        return Ok(Format::Encoded("TGA", image::ImageFormat::Tga));
    }
    // Otherwise the extension decides, so that a damaged file gets its decoder's diagnosis.
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "png" => Ok(Format::Encoded("PNG", image::ImageFormat::Png)),
        "jpg" | "jpeg" => Ok(Format::Encoded("JPEG", image::ImageFormat::Jpeg)),
        "tga" => Ok(Format::Encoded("TGA", image::ImageFormat::Tga)),
        "bmp" => Ok(Format::Encoded("BMP", image::ImageFormat::Bmp)),
        "ppm" => Ok(Format::Encoded("PPM", image::ImageFormat::Pnm)),
        "hdr" => Ok(Format::Hdr),
        "pfm" => Ok(Format::Pfm),
        "exr" => Ok(Format::Exr),
        _ => Err(ImageIoError::UnsupportedFormat {
            path: path.to_owned(),
        }),
    }
}

/// Reads a PNG, JPEG, TGA or BMP (sRGB → linear), Radiance HDR or EXR (linear) image as
/// linear RGB. Alpha is ignored; grey-scale images are expanded to three equal channels.
pub fn read_rgb_image(path: &Path) -> Result<RgbImage, ImageIoError> {
    read_rgb_image_encoded(path, false)
}

/// Like [`read_rgb_image`], but with `raw = true` the values of sRGB-encoded formats are
/// taken as they are (no decoding), as Mitsuba's `bitmap` does with `raw="true"` (e.g. for
/// roughness or normal maps). HDR and EXR images are always linear.
pub fn read_rgb_image_encoded(path: &Path, raw: bool) -> Result<RgbImage, ImageIoError> {
    match format_of(path)? {
        Format::Encoded(name, format) => read_encoded(path, (name, format), raw),
        Format::Hdr => read_hdr(path),
        Format::Pfm => read_pfm(path),
        Format::Exr => read_exr(path),
    }
}

/// An sRGB-encoded image (PNG, JPEG, TGA, BMP, PPM) decoded by the `image` crate; `raw`: the
/// encoded values as they are.
fn read_encoded(
    path: &Path,
    (name, format): (&'static str, image::ImageFormat),
    raw: bool,
) -> Result<RgbImage, ImageIoError> {
    let mut reader = image::ImageReader::open(path).map_err(|error| ImageIoError::Io {
        path: path.to_owned(),
        error,
    })?;
    reader.set_format(format);
    let decoded = reader.decode().map_err(|error| ImageIoError::Decode {
        path: path.to_owned(),
        format: name,
        error,
    })?;
    Ok(rgb_image(decoded, !raw))
}

/// A Radiance RGBE image (linear). Mitsuba writes (and it, stb_image and Radiance read) the
/// signature "#?RGBE" as well as "#?RADIANCE"; the `image` crate knows only the second.
fn read_hdr(path: &Path) -> Result<RgbImage, ImageIoError> {
    let mut bytes = std::fs::read(path).map_err(|error| ImageIoError::Io {
        path: path.to_owned(),
        error,
    })?;
    if let Some(rest) = bytes.strip_prefix(b"#?RGBE") {
        bytes = [b"#?RADIANCE".as_slice(), rest].concat();
    }
    let decoded =
        image::load_from_memory_with_format(&bytes, image::ImageFormat::Hdr).map_err(|error| {
            ImageIoError::Decode {
                path: path.to_owned(),
                format: "Radiance HDR",
                error,
            }
        })?;
    Ok(rgb_image(decoded, false))
}

/// A decoded image as linear RGB, through the sRGB curve when `srgb`.
fn rgb_image(decoded: image::DynamicImage, srgb: bool) -> RgbImage {
    let rgb = decoded.to_rgb32f();
    let (width, height) = rgb.dimensions();
    let decode = |v: f32| if srgb { fileio::srgb::decode(v) } else { v };
    let pixels = rgb
        .pixels()
        .map(|p| Rgb::new(decode(p.0[0]), decode(p.0[1]), decode(p.0[2])))
        .collect();
    (width, height, pixels)
}

/// A portable float map: a text header `PF` (RGB) or `Pf` (grey), `width height`, and a scale
/// whose sign gives the byte order (negative: little-endian), then rows of 32-bit floats from
/// the **bottom** row up.
fn read_pfm(path: &Path) -> Result<RgbImage, ImageIoError> {
    let bytes = std::fs::read(path).map_err(|error| ImageIoError::Io {
        path: path.to_owned(),
        error,
    })?;
    let bad = |why: String| ImageIoError::Pfm {
        path: path.to_owned(),
        why,
    };
    // Three whitespace-separated header fields (the size counts as two), each token ending
    // in one whitespace byte; the data follows the scale's terminator.
    let mut tokens = Vec::with_capacity(4);
    let mut at = 0;
    while tokens.len() < 4 {
        while at < bytes.len() && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len() && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        if start == at || at >= bytes.len() {
            return Err(bad("truncated header".into()));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
        at += 1;
    }
    let channels = match tokens[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        other => return Err(bad(format!("not a PFM file (starts with {other:?})"))),
    };
    let dim = |t: &str, name: &str| -> Result<u32, ImageIoError> {
        t.parse::<u32>()
            .ok()
            .filter(|&v| v > 0)
            .ok_or_else(|| bad(format!("bad {name} {t:?}")))
    };
    let (width, height) = (dim(&tokens[1], "width")?, dim(&tokens[2], "height")?);
    let scale: f32 = tokens[3]
        .parse()
        .ok()
        .filter(|v: &f32| *v != 0.0 && v.is_finite())
        .ok_or_else(|| bad(format!("bad scale {:?}", tokens[3])))?;
    let count = width as u64 * height as u64 * channels;
    let data = &bytes[at..];
    if (data.len() as u64) < 4 * count {
        return Err(bad(format!(
            "{} bytes of pixel data for a {width}x{height} image of {channels} channel(s)",
            data.len()
        )));
    }
    let value = |i: usize| {
        let b = [
            data[4 * i],
            data[4 * i + 1],
            data[4 * i + 2],
            data[4 * i + 3],
        ];
        if scale < 0.0 {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let (w, h, c) = (width as usize, height as usize, channels as usize);
    let mut pixels = Vec::with_capacity(w * h);
    for row in (0..h).rev() {
        for x in 0..w {
            let i = (row * w + x) * c;
            pixels.push(if c == 3 {
                Rgb::new(value(i), value(i + 1), value(i + 2))
            } else {
                Rgb::splat(value(i))
            });
        }
    }
    Ok((width, height, pixels))
}

fn read_exr(path: &Path) -> Result<RgbImage, ImageIoError> {
    use fileio::exr::ExrReadError;
    let read = fileio::exr::read_channels(path).map_err(|e| match e {
        ExrReadError::Io(error) => ImageIoError::Io {
            path: path.to_owned(),
            error,
        },
        ExrReadError::Exr(error) => exr_error(path, error),
        e @ ExrReadError::DataWindow(_) => ImageIoError::ExrLayout {
            path: path.to_owned(),
            why: e.to_string(),
        },
    })?;
    let [r, g, b] = fileio::exr::RGB.map(|name| {
        read.planes
            .get(name)
            .filter(|plane| plane.len() == read.width * read.height)
            .ok_or_else(|| ImageIoError::ExrLayout {
                path: path.to_owned(),
                why: format!(
                    "no channel `{name}` of {}x{} pixels",
                    read.width, read.height
                ),
            })
    });
    let (r, g, b) = (r?, g?, b?);
    let pixels = (0..read.width * read.height)
        .map(|i| Rgb::new(r[i], g[i], b[i]))
        .collect();
    Ok((read.width as u32, read.height as u32, pixels))
}

fn check_size(path: &Path, width: u32, height: u32, pixels: &[Rgb]) -> Result<(), ImageIoError> {
    if pixels.len() as u64 != width as u64 * height as u64 || width == 0 || height == 0 {
        return Err(ImageIoError::SizeMismatch {
            path: path.to_owned(),
            width,
            height,
            len: pixels.len(),
        });
    }
    Ok(())
}

/// The renderer's error for a failed [`fileio::exr`] write of `path`.
fn exr_write_error(path: &Path, error: fileio::exr::ExrError) -> ImageIoError {
    use fileio::exr::ExrError;
    let path = path.to_owned();
    match error {
        ExrError::Io(error) => ImageIoError::Io { path, error },
        ExrError::Exr(error) => exr_error(&path, error),
        ExrError::ChannelName { name, why } => ImageIoError::ChannelName { path, name, why },
        ExrError::Header(why) => ImageIoError::ExrLayout { path, why },
        ExrError::Size {
            width, height, len, ..
        } => ImageIoError::SizeMismatch {
            path,
            width: width as u32,
            height: height as u32,
            len,
        },
    }
}

/// The error of reading or writing the EXR `path`: an I/O error as such, anything else as the
/// EXR's.
fn exr_error(path: &Path, error: exr::error::Error) -> ImageIoError {
    match error {
        exr::error::Error::Io(error) => ImageIoError::Io {
            path: path.to_owned(),
            error,
        },
        error => ImageIoError::Exr {
            path: path.to_owned(),
            error,
        },
    }
}

/// Writes a float32 RGB OpenEXR (channels `R`, `G`, `B`), atomically, through
/// [`fileio::exr`] (ZIP-compressed in increasing line order: the file's bytes are a function of
/// the pixels alone).
pub fn write_rgb_exr(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Rgb],
) -> Result<(), ImageIoError> {
    check_size(path, width, height, pixels)?;
    let planes = [0, 1, 2].map(|c| pixels.iter().map(|p| p[c]).collect());
    fileio::exr::write_rgb(path, width as usize, height as usize, planes)
        .map_err(|e| exr_write_error(path, e))
}

/// Writes a float32 OpenEXR of named channels (`(name, plane)`, each plane `width`·`height`
/// values, rows top to bottom), atomically, like [`write_rgb_exr`]. The file lists the channels
/// sorted by name, as OpenEXR requires; a name OpenEXR cannot store (empty, longer than 255
/// bytes, with a NUL) is refused.
pub fn write_channels_exr(
    path: &Path,
    width: u32,
    height: u32,
    channels: Vec<(String, Vec<f32>)>,
) -> Result<(), ImageIoError> {
    let pixels = width as usize * height as usize;
    if let Some((name, why)) = channels
        .iter()
        .find_map(|(name, _)| fileio::exr::channel_name_problem(name).map(|why| (name, why)))
    {
        return Err(ImageIoError::ChannelName {
            path: path.to_owned(),
            name: name.clone(),
            why,
        });
    }
    if let Some((_, plane)) = channels.iter().find(|(_, p)| p.len() != pixels) {
        return Err(ImageIoError::SizeMismatch {
            path: path.to_owned(),
            width,
            height,
            len: plane.len(),
        });
    }
    fileio::exr::write_channels(path, width as usize, height as usize, channels, &[])
        .map_err(|e| exr_write_error(path, e))
}

/// Writes an 8-bit sRGB PNG: linear values clamped to [0, 1] and gamma-encoded, atomically.
pub fn write_png_srgb(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Rgb],
) -> Result<(), ImageIoError> {
    check_size(path, width, height, pixels)?;
    let bytes: Vec<u8> = pixels
        .iter()
        .flat_map(|p| [p.x, p.y, p.z].map(fileio::srgb::encode8))
        .collect();
    fileio::png::write_rgb8(path, width as usize, height as usize, &bytes).map_err(|e| {
        let path = path.to_owned();
        match e {
            fileio::png::PngError::Encode(error) => ImageIoError::Png { path, error },
            fileio::png::PngError::Io(error) => ImageIoError::Io { path, error },
            fileio::png::PngError::Size { len, .. } => ImageIoError::SizeMismatch {
                path,
                width,
                height,
                len: len / 3,
            },
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("renderer-image-io-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn gradient(w: u32, h: u32) -> Vec<Rgb> {
        (0..w * h)
            .map(|i| {
                Rgb::new(
                    i as f32 * 0.37,
                    (i % 3) as f32 * 0.25,
                    1.0 / (i as f32 + 1.0),
                )
            })
            .collect()
    }

    #[test]
    fn exr_round_trip_is_exact() {
        let dir = temp_dir("exr");
        let path = dir.join("a.exr");
        let pixels = gradient(5, 3);
        write_rgb_exr(&path, 5, 3, &pixels).unwrap();
        let (w, h, back) = read_rgb_image(&path).unwrap();
        assert_eq!((w, h), (5, 3));
        assert_eq!(back, pixels);
        // No temporary file is left behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    }

    #[test]
    fn named_channels_round_trip_and_bad_names_are_refused() {
        let dir = temp_dir("channels");
        let path = dir.join("c.exr");
        let planes = vec![
            ("dd.y.T".to_string(), vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]),
            (
                "✓ normal.X".to_string(),
                vec![-1.0, 0.5, 0.0, 7.0, 8.0, 9.0],
            ),
        ];
        write_channels_exr(&path, 3, 2, planes.clone()).unwrap();
        let image = exr::prelude::read_all_flat_layers_from_file(&path).unwrap();
        let mut back: Vec<(Vec<u8>, Vec<f32>)> = image.layer_data[0]
            .channel_data
            .list
            .iter()
            .map(|c| {
                let values = c.sample_data.values_as_f32().collect();
                (c.name.bytes().to_vec(), values)
            })
            .collect();
        back.sort_by(|a, b| a.0.cmp(&b.0));
        let mut expected: Vec<_> = planes
            .into_iter()
            .map(|(n, p)| (n.into_bytes(), p))
            .collect();
        expected.sort_by(|a, b| a.0.cmp(&b.0));
        assert_eq!(back, expected);
        // A name OpenEXR cannot hold, or a plane of the wrong size: an error, no file.
        for (name, len) in [(String::new(), 6), ("n".repeat(256), 6), ("a".into(), 5)] {
            let bad = dir.join("bad.exr");
            let err = write_channels_exr(&bad, 3, 2, vec![(name, vec![0.0; len])]).unwrap_err();
            assert!(err.to_string().contains("bad.exr"), "{err}");
            assert!(!bad.exists());
        }
    }

    #[test]
    fn exr_bytes_depend_on_the_pixels_alone() {
        // Large enough for many compressed blocks, which compress on several threads.
        let dir = temp_dir("exr-bytes");
        let (w, h) = (301u32, 203u32);
        let pixels: Vec<Rgb> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                Rgb::new(
                    (x * 0.37).sin(),
                    y / h as f32,
                    ((x + y) * 0.01).cos().abs() * 9.0,
                )
            })
            .collect();
        let bytes: Vec<Vec<u8>> = (0..6)
            .map(|k| {
                let path = dir.join(format!("{k}.exr"));
                write_rgb_exr(&path, w, h, &pixels).unwrap();
                std::fs::read(&path).unwrap()
            })
            .collect();
        assert!(
            bytes.iter().all(|b| *b == bytes[0]),
            "EXR bytes differ between writes"
        );
        let (rw, rh, back) = read_rgb_image(&dir.join("0.exr")).unwrap();
        assert_eq!((rw, rh), (w, h));
        assert!(back.iter().zip(&pixels).all(|(a, b)| a == b));
    }

    #[test]
    fn png_round_trip_within_quantisation() {
        let dir = temp_dir("png");
        let path = dir.join("a.png");
        let pixels: Vec<Rgb> = (0..12)
            .map(|i| Rgb::splat(i as f32 / 11.0) * Rgb::new(1.0, 0.5, 0.25))
            .collect();
        write_png_srgb(&path, 4, 3, &pixels).unwrap();
        let (w, h, back) = read_rgb_image(&path).unwrap();
        assert_eq!((w, h), (4, 3));
        for (a, b) in pixels.iter().zip(&back) {
            // One 8-bit step in sRGB is at most ~1.3 % of full scale in linear.
            assert!((*a - *b).abs().max_element() < 0.007, "{a} vs {b}");
        }
        // Raw reading returns the encoded values.
        let (_, _, raw) = read_rgb_image_encoded(&path, true).unwrap();
        assert!((raw[11].x - 1.0).abs() < 1e-6);
        assert!((raw[11].y - fileio::srgb::encode(0.5)).abs() < 0.003);
    }

    #[test]
    fn jpeg_tga_bmp_are_srgb_and_hdr_is_linear() {
        // Written by the `image` crate's encoders: 8×8 blocks of flat sRGB colours (JPEG keeps
        // flat blocks within a step or two at quality 100), and linear floats as RGBE.
        let dir = temp_dir("formats");
        let (w, h) = (16u32, 8u32);
        let encoded = |x: u32| {
            if x < 8 {
                [200u8, 100, 30]
            } else {
                [20, 240, 128]
            }
        };
        let rgb8 = image::RgbImage::from_fn(w, h, |x, _| image::Rgb(encoded(x)));
        let expect = |x: u32| {
            let e = encoded(x).map(|c| fileio::srgb::decode(c as f32 / 255.0));
            Rgb::new(e[0], e[1], e[2])
        };
        for (name, tolerance) in [
            ("a.tga", 1e-6),
            ("a.bmp", 1e-6),
            ("a.ppm", 1e-6),
            ("a.jpg", 0.02),
        ] {
            let path = dir.join(name);
            if name.ends_with("ppm") {
                write_binary_ppm(&path, &rgb8);
            } else if name.ends_with("jpg") {
                let mut file = std::fs::File::create(&path).unwrap();
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut file, 100)
                    .encode_image(&rgb8)
                    .unwrap();
            } else {
                rgb8.save(&path).unwrap();
            }
            let (rw, rh, px) = read_rgb_image(&path).unwrap();
            assert_eq!((rw, rh), (w, h), "{name}");
            for (i, p) in px.iter().enumerate() {
                let want = expect(i as u32 % w);
                assert!(
                    (*p - want).abs().max_element() < tolerance,
                    "{name}: {p} vs {want}"
                );
            }
            // `raw`: the encoded values.
            let (_, _, raw) = read_rgb_image_encoded(&path, true).unwrap();
            assert!(
                (raw[0].x - 200.0 / 255.0).abs() < tolerance.max(1e-6) * 4.0,
                "{name}"
            );
        }
        let linear: Vec<image::Rgb<f32>> = (0..w * h)
            .map(|i| image::Rgb([0.25 * i as f32, 3.5, 1e-3 * (i + 1) as f32]))
            .collect();
        let path = dir.join("a.hdr");
        image::codecs::hdr::HdrEncoder::new(std::fs::File::create(&path).unwrap())
            .encode(&linear, w as usize, h as usize)
            .unwrap();
        // The same file with the signature Mitsuba writes ("#?RGBE").
        let bytes = std::fs::read(&path).unwrap();
        let rgbe = dir.join("rgbe.hdr");
        let body = bytes
            .strip_prefix(b"#?RADIANCE".as_slice())
            .expect("signature");
        std::fs::write(&rgbe, [b"#?RGBE".as_slice(), body].concat()).unwrap();
        for (path, raw) in [(&path, false), (&path, true), (&rgbe, false)] {
            let (_, _, px) = read_rgb_image_encoded(path, raw).unwrap();
            for (p, q) in px.iter().zip(&linear) {
                let want = Rgb::new(q.0[0], q.0[1], q.0[2]);
                // RGBE keeps 8 bits of mantissa under a shared exponent: ~1 % of the largest
                // channel.
                let scale = want.max_element();
                assert!(
                    (*p - want).abs().max_element() <= 0.01 * scale,
                    "{p} vs {want}"
                );
            }
        }
        // A corrupt JPEG names the file and the format.
        let bad = dir.join("bad.jpg");
        std::fs::write(&bad, b"\xff\xd8 not really").unwrap();
        let e = read_rgb_image(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.jpg") && e.contains("JPEG"), "{e}");
    }

    /// Writes a binary PPM (`P6`), the one kind Mitsuba reads (the `image` crate writes PAM).
    fn write_binary_ppm(path: &Path, image: &image::RgbImage) {
        use image::codecs::pnm::{PnmEncoder, PnmSubtype, SampleEncoding};
        let file = std::fs::File::create(path).unwrap();
        PnmEncoder::new(file)
            .with_subtype(PnmSubtype::Pixmap(SampleEncoding::Binary))
            .encode(
                image.as_raw().as_slice(),
                image.width(),
                image.height(),
                image::ExtendedColorType::Rgb8,
            )
            .unwrap();
        assert!(std::fs::read(path).unwrap().starts_with(b"P6"));
    }

    /// As Mitsuba, the first bytes of a file decide its format, not its name; the name decides
    /// only where they say nothing.
    #[test]
    fn formats_are_known_by_their_contents() {
        let dir = temp_dir("sniff");
        let rgb8 =
            image::RgbImage::from_fn(3, 2, |x, y| image::Rgb([40 * x as u8, 90 * y as u8, 7]));
        let expect = |i: usize| {
            let (x, y) = ((i % 3) as f32, (i / 3) as f32);
            Rgb::new(40.0 * x, 90.0 * y, 7.0) / 255.0
        };
        let tga = dir.join("a.tga");
        rgb8.save(&tga).unwrap();
        let tga_bytes = std::fs::read(&tga).unwrap();
        for (name, format) in [
            ("png.exr", image::ImageFormat::Png),
            ("jpeg.png", image::ImageFormat::Jpeg),
            ("bmp.texture", image::ImageFormat::Bmp),
            ("ppm", image::ImageFormat::Pnm),
        ] {
            let path = dir.join(name);
            if format == image::ImageFormat::Pnm {
                write_binary_ppm(&path, &rgb8);
            } else {
                rgb8.save_with_format(&path, format).unwrap();
            }
            let (w, h, px) = read_rgb_image_encoded(&path, true).unwrap();
            assert_eq!((w, h), (3, 2), "{name}");
            let tolerance = if format == image::ImageFormat::Jpeg {
                0.1
            } else {
                1e-6
            };
            for (i, p) in px.iter().enumerate() {
                assert!(
                    (*p - expect(i)).abs().max_element() < tolerance,
                    "{name}: {p}"
                );
            }
        }
        // A TGA is known by its version-2 footer, or else by its name.
        let footer = b"\0\0\0\0\0\0\0\0TRUEVISION-XFILE.\0";
        let v2 = dir.join("v2.image");
        std::fs::write(&v2, [tga_bytes.as_slice(), footer].concat()).unwrap();
        let v1 = dir.join("v1.image");
        std::fs::write(&v1, &tga_bytes).unwrap();
        assert_eq!(read_rgb_image_encoded(&v2, true).unwrap().2[5], expect(5));
        let e = read_rgb_image(&v1).unwrap_err().to_string();
        assert!(e.contains("v1.image: unsupported image format"), "{e}");
        // A damaged file whose first bytes say nothing is diagnosed by its name's decoder.
        let damaged = dir.join("damaged.exr");
        std::fs::write(&damaged, b"not an exr").unwrap();
        let e = read_rgb_image(&damaged).unwrap_err().to_string();
        assert!(e.contains("damaged.exr: OpenEXR"), "{e}");
    }

    #[test]
    fn pfm_rows_run_bottom_up_in_either_byte_order() {
        let dir = temp_dir("pfm");
        // A 2×2 colour map: file rows bottom-up, so the first triple is the bottom-left pixel.
        let values: [f32; 12] = [
            1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.5, -0.25, 1e6,
        ];
        let file = |header: &str, big: bool| {
            let mut bytes = header.as_bytes().to_vec();
            for v in values {
                bytes.extend(if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
            bytes
        };
        let want = [
            Rgb::new(7.0, 8.0, 9.0),
            Rgb::new(10.5, -0.25, 1e6),
            Rgb::new(1.0, 2.0, 3.0),
            Rgb::new(4.0, 5.0, 6.0),
        ];
        for (name, header, big) in [
            ("le.pfm", "PF\n2 2\n-1.0\n", false),
            ("be.pfm", "PF\n2 2\n1.0\n", true),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, file(header, big)).unwrap();
            // `raw` makes no difference: floats are linear.
            for raw in [false, true] {
                let (w, h, px) = read_rgb_image_encoded(&path, raw).unwrap();
                assert_eq!((w, h), (2, 2));
                assert_eq!(px, want, "{name}");
            }
        }
        // Grey: one channel, expanded.
        let path = dir.join("grey.pfm");
        let mut bytes = b"Pf 3 1 -1\n".to_vec();
        for v in [0.5f32, 1.5, 2.5] {
            bytes.extend(v.to_le_bytes());
        }
        std::fs::write(&path, bytes).unwrap();
        let (_, _, px) = read_rgb_image(&path).unwrap();
        assert_eq!(px, vec![Rgb::splat(0.5), Rgb::splat(1.5), Rgb::splat(2.5)]);
        // Malformed files name the file and what is wrong.
        for (name, bytes, needle) in [
            (
                "short.pfm",
                b"PF\n2 2\n-1.0\n\0\0\0\0".to_vec(),
                "bytes of pixel data",
            ),
            ("magic.pfm", b"P7\n2 2\n255\n".to_vec(), "not a PFM"),
            ("size.pfm", b"PF\n0 2\n-1\n".to_vec(), "bad width"),
            ("header.pfm", b"PF\n2".to_vec(), "truncated header"),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, bytes).unwrap();
            let e = read_rgb_image(&path).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(needle), "{e}");
        }
    }

    #[test]
    fn srgb_curve_round_trips() {
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((fileio::srgb::decode(fileio::srgb::encode(v)) - v).abs() < 1e-5);
        }
        assert!((fileio::srgb::decode(0.5) - 0.214_041).abs() < 1e-5);
    }

    /// Every error names its file, and states its cause once: the cause is in the message and
    /// is not also a `source`, which `{:#}` chains (the binaries' error output) would repeat.
    #[test]
    fn errors_name_the_file_once_with_the_cause() {
        use std::error::Error;
        let dir = temp_dir("errors");
        let garbage_exr = dir.join("garbage.exr");
        std::fs::write(&garbage_exr, b"not an exr").unwrap();
        let garbage_png = dir.join("garbage.png");
        std::fs::write(&garbage_png, b"not a png").unwrap();
        let cases = [
            (
                "missing.exr",
                read_rgb_image(&dir.join("missing.exr")).unwrap_err(),
            ),
            (
                "missing.png",
                read_rgb_image(&dir.join("missing.png")).unwrap_err(),
            ),
            ("garbage.exr", read_rgb_image(&garbage_exr).unwrap_err()),
            ("garbage.png", read_rgb_image(&garbage_png).unwrap_err()),
            ("x.jpg", read_rgb_image(&dir.join("x.jpg")).unwrap_err()),
            ("x.ppm", read_rgb_image(&dir.join("x.ppm")).unwrap_err()),
            (
                "short.exr",
                write_rgb_exr(&dir.join("short.exr"), 2, 2, &[Rgb::ZERO; 3]).unwrap_err(),
            ),
            (
                "nodir/x.png",
                write_png_srgb(&dir.join("nodir/x.png"), 1, 1, &[Rgb::ZERO]).unwrap_err(),
            ),
        ];
        for (name, e) in cases {
            let message = e.to_string();
            assert!(message.contains(name), "{message}");
            assert!(e.source().is_none(), "{name}: the cause would print twice");
            assert_eq!(format!("{:#}", anyhow::Error::from(e)), message);
        }
        let missing = read_rgb_image(&dir.join("missing.exr"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("No such file"), "{missing}");
    }
}
