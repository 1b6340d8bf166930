//! The sRGB transfer curve (IEC 61966-2-1) both ways, and the 8-bit quantisation every PNG the
//! toolkit writes goes through, so that a pixel value means the same picture everywhere.

/// The sRGB electro-optical transfer function: encoded value in [0, 1] → linear.
pub fn decode(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// [`decode`] in double precision (values at or below 0.04045, negative ones included, on the
/// linear branch), for attributes read as doubles.
pub fn decode_f64(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The inverse transfer function: linear → encoded value. Inputs are clamped to [0, 1]; NaN
/// encodes as 0.
pub fn encode(v: f32) -> f32 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// A linear value as an 8-bit sRGB code (clamped to [0, 1], NaN → 0, rounded to nearest).
pub fn encode8(v: f32) -> u8 {
    (encode(v) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_round_trips_and_meets_its_anchors() {
        for i in 0..=1000 {
            let v = i as f32 / 1000.0;
            assert!((decode(encode(v)) - v).abs() < 1e-5, "{v}");
            assert!((decode_f64(f64::from(encode(v))) - f64::from(v)).abs() < 1e-5);
        }
        assert_eq!(encode8(0.0), 0);
        assert_eq!(encode8(1.0), 255);
        assert_eq!(encode8(2.0), 255);
        assert_eq!(encode8(-1.0), 0);
        assert_eq!(encode8(f32::NAN), 0);
        // Every 8-bit code decodes to a value that encodes back to it; mid-grey, encoded 0.5,
        // is linear 0.2140, just under code 128 (0.50196).
        for code in 0..=255u8 {
            assert_eq!(encode8(decode(f32::from(code) / 255.0)), code);
        }
        assert!((decode(0.5) - 0.214_041).abs() < 1e-5);
        assert_eq!(encode8(0.214_041), 127);
        // The two branches meet: 12.92 · 0.0031308 = 0.04045.
        assert!((encode(0.003_130_8) - 0.04045).abs() < 1e-6);
    }
}
