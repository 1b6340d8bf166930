//! 8-bit RGB PNG, the format of every preview, contact sheet, comparison and weight map: in
//! memory (for pages that embed their pictures) or as a file, written atomically.

use std::path::Path;

use crate::atomic::write_with;

/// Why a PNG could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PngError {
    /// `bytes` does not hold `width`·`height` RGB pixels.
    #[error("{width}x{height} RGB needs {} bytes, got {len}", width * height * 3)]
    Size {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Bytes given.
        len: usize,
    },
    /// The encoder failed.
    #[error("{0}")]
    Encode(#[from] image::ImageError),
    /// Writing the file failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

fn check(width: usize, height: usize, bytes: &[u8]) -> Result<(), PngError> {
    if bytes.len() != width * height * 3 {
        return Err(PngError::Size {
            width,
            height,
            len: bytes.len(),
        });
    }
    Ok(())
}

/// Encodes interleaved 8-bit RGB (`width`·`height`·3 bytes, rows top to bottom) as PNG.
pub fn encode_rgb8(width: usize, height: usize, bytes: &[u8]) -> Result<Vec<u8>, PngError> {
    check(width, height, bytes)?;
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(
        &mut out,
        bytes,
        width as u32,
        height as u32,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )?;
    Ok(out.into_inner())
}

/// Writes interleaved 8-bit RGB to `path` as PNG, atomically.
pub fn write_rgb8(path: &Path, width: usize, height: usize, bytes: &[u8]) -> Result<(), PngError> {
    check(width, height, bytes)?;
    write_with(path, |tmp| {
        image::save_buffer_with_format(
            tmp,
            bytes,
            width as u32,
            height as u32,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(PngError::from)
    })
    .map_err(|e| e.into_error(PngError::Io))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_and_memory_encodings_agree_and_decode_to_the_pixels() {
        let dir = std::env::temp_dir().join(format!("fileio-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (5, 3);
        let bytes: Vec<u8> = (0..w * h * 3).map(|i| (i * 17 % 256) as u8).collect();
        let path = dir.join("a.png");
        write_rgb8(&path, w, h, &bytes).unwrap();
        let file = std::fs::read(&path).unwrap();
        assert_eq!(file, encode_rgb8(w, h, &bytes).unwrap());
        let back = image::load_from_memory(&file).unwrap().to_rgb8();
        assert_eq!((back.width(), back.height()), (w as u32, h as u32));
        assert_eq!(back.into_raw(), bytes);
        let err = write_rgb8(&dir.join("b.png"), w, h, &bytes[1..]).unwrap_err();
        assert!(err.to_string().contains("needs 45 bytes, got 44"), "{err}");
        assert!(!dir.join("b.png").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
