//! Colour values: linear sRGB triples, and conversion of spectra to them.

/// A linear-sRGB colour (radiance, reflectance, flux…); channels are R, G, B.
pub type Rgb = glam::Vec3;

/// Luminance (Rec. 709 / sRGB primaries) of a linear-sRGB colour.
pub fn luminance(c: Rgb) -> f32 {
    0.212_671 * c.x + 0.715_160 * c.y + 0.072_169 * c.z
}
