//! What the toolkit's PNG plots share (`evaluate`'s convergence plots, `train`'s curves, the
//! renderer's validation figures): the font compiled into the binary, so drawing text needs no
//! system fonts or fontconfig; one colour per estimate, the same in every picture; log axes
//! with readable ticks ([`LogAxis`]); series whose legend swatch matches their line, with the
//! legend in the corner that covers the fewest data ([`draw_series`], [`draw_legend`]); and
//! writing a picture atomically.

use std::error::Error;

mod series;
mod ticks;

pub use series::{
    draw_legend, draw_series, legend_size, pick_corner, swatch, Series, DASH, LEGEND_FONT,
    LEGEND_INSET,
};
use std::path::Path;
pub use ticks::{binary_log_ticks, decimal_log_ticks, tick_label, LogAxis, LogTicks};

use plotters::style::{FontStyle, RGBColor};

/// Colours of the input levels ỹ, z̃1..z̃4, in that order.
pub const LEVEL_COLOURS: [RGBColor; 5] = [
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0x7f, 0x7f, 0x7f),
];
/// Colour of our reconstruction (and of the network's training loss).
pub const OURS: RGBColor = RGBColor(0xd6, 0x27, 0x28);
/// Colour of standard (single-level) SPPM.
pub const STANDARD: RGBColor = RGBColor(0x1f, 0x77, 0xb4);

/// Makes the embedded DejaVu Sans plotters' `sans-serif` (once per process; later calls return
/// the first one's outcome). Call before drawing any text.
pub fn register_font() -> Result<(), String> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
    });
    if *ok {
        Ok(())
    } else {
        Err("the embedded font (DejaVu Sans) does not load".into())
    }
}

/// Registers the font, lets `draw` write the picture to a temporary file next to `path` (its
/// name also ends in the extension of `path`, from which plotters picks the encoder), then
/// renames it to `path`: a reader never sees half a picture. The temporary file is removed
/// when drawing fails. Errors name `path`.
pub fn write_atomically(
    path: &Path,
    draw: impl FnOnce(&Path) -> Result<(), Box<dyn Error>>,
) -> Result<(), String> {
    fileio::atomic::write_with(path, |tmp| {
        register_font()
            .map_err(|e| e.into())
            .and_then(|()| draw(tmp))
    })
    .map_err(|e| match e {
        fileio::atomic::AtomicError::Write(e) => format!("drawing {}: {e}", path.display()),
        fileio::atomic::AtomicError::Commit(e) => format!("writing {}: {e}", path.display()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use plotters::prelude::*;

    /// Text draws with the embedded font (whatever fonts the machine has), the picture appears
    /// under its name only, and a failed drawing leaves nothing behind.
    #[test]
    fn draws_text_and_writes_atomically() {
        let dir = std::env::temp_dir().join(format!("plots-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("text.png");
        write_atomically(&path, |p| {
            let root = BitMapBackend::new(p, (200, 60)).into_drawing_area();
            root.fill(&WHITE)?;
            root.titled("relMSE 1e-3", ("sans-serif", 20))?;
            root.present()?;
            Ok(())
        })
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
        let failed = dir.join("failed.png");
        let err = write_atomically(&failed, |_| Err("no data".into())).unwrap_err();
        assert!(
            err.contains("failed.png") && err.contains("no data"),
            "{err}"
        );
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["text.png".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
