//! Colour values: linear sRGB triples, and conversion of spectra to them (as Mitsuba 3's RGB
//! variants do it: spectra are integrated against the CIE 1931 curves when the scene is loaded).

/// A linear-sRGB colour (radiance, reflectance, flux…); channels are R, G, B.
pub type Rgb = glam::Vec3;

/// Luminance (Rec. 709 / sRGB primaries) of a linear-sRGB colour.
pub fn luminance(c: Rgb) -> f32 {
    0.212_671 * c.x + 0.715_160 * c.y + 0.072_169 * c.z
}

/// Shortest wavelength (nm) of the CIE tables.
pub const CIE_MIN: f64 = 360.0;
/// Longest wavelength (nm) of the CIE tables.
pub const CIE_MAX: f64 = 830.0;
/// Number of 5 nm samples in the CIE tables.
const CIE_SAMPLES: usize = 95;

/// 1 / ∫ȳ(λ) dλ over the tables (the integral as Mitsuba 3 evaluates it): a spectrum equal to
/// one everywhere then has luminance Y = 1.
const CIE_Y_NORMALIZATION: f64 = 1.0 / 106.750_259_399_414_06;

/// 1 / ∫ȳ(λ)·D65(λ) dλ / ∫ȳ dλ-style scale that makes the tabulated D65 illuminant (100 at
/// 560 nm) integrate to luminance 1.
const CIE_D65_NORMALIZATION: f64 = 1.0 / 98.997_417_518_762_55;

/// Number of evenly spaced wavelengths used to integrate a spectrum (Mitsuba's choice, so that
/// colours agree with Mitsuba to float precision).
const INTEGRATION_STEPS: usize = 1000;

/// Whether a `<spectrum>` describes light emission or a bounded quantity such as a reflectance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpectrumKind {
    /// A reflectance or transmittance: weighted by the D65 illuminant (so a constant spectrum
    /// of 1 is white (1, 1, 1)) and clamped to [0, 1].
    Reflectance,
    /// An unbounded non-emission quantity (e.g. an index of refraction): D65-weighted like a
    /// reflectance, clamped only below at 0.
    Unbounded,
    /// Emitted radiance/intensity: integrated without illuminant weighting (a constant
    /// spectrum is slightly purple in sRGB, as in Mitsuba's RGB variants), clamped below at 0.
    Emission,
}

/// Linear interpolation in a 5 nm table starting at [`CIE_MIN`]; zero outside the table.
fn table_lookup<const N: usize>(table: &[[f32; N]; CIE_SAMPLES], lambda: f64) -> [f64; N] {
    if !(CIE_MIN..=CIE_MAX).contains(&lambda) {
        return [0.0; N];
    }
    let t = (lambda - CIE_MIN) * ((CIE_SAMPLES - 1) as f64 / (CIE_MAX - CIE_MIN));
    let i0 = (t as usize).min(CIE_SAMPLES - 2);
    let w1 = t - i0 as f64;
    let mut out = [0.0; N];
    for (c, o) in out.iter_mut().enumerate() {
        *o = (1.0 - w1) * table[i0][c] as f64 + w1 * table[i0 + 1][c] as f64;
    }
    out
}

/// The CIE 1931 colour matching functions (x̄, ȳ, z̄) at `lambda` nm (zero outside 360–830 nm).
pub fn cie1931_xyz(lambda: f64) -> [f64; 3] {
    table_lookup(&CIE_1931_XYZ, lambda)
}

/// The CIE D65 illuminant at `lambda` nm, scaled to unit luminance.
pub fn cie_d65(lambda: f64) -> f64 {
    // Reuse the table interpolation through a one-column view of the D65 table.
    let column: &[[f32; 1]; CIE_SAMPLES] = {
        // A [f32; N] and a [[f32; 1]; N] have the same layout; build the view without unsafe
        // code by copying once per call (95 floats: negligible at load time).
        &CIE_D65.map(|v| [v])
    };
    table_lookup(column, lambda)[0] * CIE_D65_NORMALIZATION
}

/// CIE XYZ → linear sRGB (D65 white point), with the matrix Mitsuba 3 uses.
pub fn xyz_to_srgb(xyz: [f64; 3]) -> Rgb {
    let [x, y, z] = xyz;
    Rgb::new(
        (3.240_479 * x - 1.537_150 * y - 0.498_535 * z) as f32,
        (-0.969_256 * x + 1.875_991 * y + 0.041_556 * z) as f32,
        (0.055_648 * x - 0.204_043 * y + 1.057_311 * z) as f32,
    )
}

/// A spectrum given as `(wavelength nm, value)` pairs with increasing wavelengths, converted to
/// linear sRGB as Mitsuba 3's RGB variants do (`spectrum_list_to_srgb`): the piecewise-linear
/// spectrum (zero outside its first and last wavelength) is integrated against the CIE 1931
/// curves at 1000 evenly spaced wavelengths over 360–830 nm, D65-weighted unless it is an
/// emission spectrum, normalised to unit luminance of a constant spectrum, converted XYZ →
/// sRGB and clamped as [`SpectrumKind`] says.
///
/// The caller guarantees at least one pair and strictly increasing wavelengths (the XML
/// importer checks both); otherwise the result is black.
pub fn spectrum_list_to_srgb(pairs: &[(f64, f64)], kind: SpectrumKind) -> Rgb {
    let (Some(first), Some(last)) = (pairs.first(), pairs.last()) else {
        return Rgb::ZERO;
    };
    let d65 = kind != SpectrumKind::Emission;
    let mut xyz = [0.0f64; 3];
    for i in 0..INTEGRATION_STEPS {
        let w = CIE_MIN + (i as f64 / (INTEGRATION_STEPS - 1) as f64) * (CIE_MAX - CIE_MIN);
        if w < first.0 || w > last.0 {
            continue;
        }
        // The last pair whose wavelength is <= w (clamped so that [idx, idx + 1] is valid).
        let idx = pairs
            .partition_point(|p| p.0 <= w)
            .saturating_sub(1)
            .min(pairs.len().saturating_sub(2));
        let v = if pairs.len() == 1 {
            first.1
        } else {
            let (w0, v0) = pairs[idx];
            let (w1, v1) = pairs[idx + 1];
            ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1)
        };
        let weight = v * if d65 { cie_d65(w) } else { 1.0 };
        let cmf = cie1931_xyz(w);
        for c in 0..3 {
            xyz[c] += cmf[c] * weight;
        }
    }
    let scale = (CIE_MAX - CIE_MIN) * CIE_Y_NORMALIZATION / INTEGRATION_STEPS as f64;
    let rgb = xyz_to_srgb(xyz.map(|v| v * scale));
    match kind {
        SpectrumKind::Reflectance => rgb.clamp(Rgb::ZERO, Rgb::ONE),
        SpectrumKind::Unbounded | SpectrumKind::Emission => rgb.max(Rgb::ZERO),
    }
}

/// A wavelength-independent spectrum of value `v`, as linear sRGB. Reflectances stay grey
/// (v, v, v); an emission spectrum equal to `v` everywhere becomes `v · xyz_to_srgb(1, 1, 1)`
/// (slightly purple, since sRGB's white is D65, not equal energy), as Mitsuba's RGB variants do.
pub fn uniform_spectrum_to_srgb(v: f64, kind: SpectrumKind) -> Rgb {
    match kind {
        SpectrumKind::Emission => xyz_to_srgb([v, v, v]),
        SpectrumKind::Reflectance | SpectrumKind::Unbounded => Rgb::splat(v as f32),
    }
}

/// CIE 1931 2° standard observer colour matching functions (x̄, ȳ, z̄), tabulated by the CIE
/// every 5 nm from [`CIE_MIN`] to [`CIE_MAX`].
#[rustfmt::skip]
const CIE_1931_XYZ: [[f32; 3]; CIE_SAMPLES] = [
    [0.0001299, 3.917e-06, 0.0006061], // 360 nm
    [0.0002321, 6.965e-06, 0.001086], // 365 nm
    [0.0004149, 1.239e-05, 0.001946], // 370 nm
    [0.0007416, 2.202e-05, 0.003486], // 375 nm
    [0.001368, 3.9e-05, 0.006450001], // 380 nm
    [0.002236, 6.4e-05, 0.01054999], // 385 nm
    [0.004243, 0.00012, 0.02005001], // 390 nm
    [0.00765, 0.000217, 0.03621], // 395 nm
    [0.01431, 0.000396, 0.06785001], // 400 nm
    [0.02319, 0.00064, 0.1102], // 405 nm
    [0.04351, 0.00121, 0.2074], // 410 nm
    [0.07763, 0.00218, 0.3713], // 415 nm
    [0.13438, 0.004, 0.6456], // 420 nm
    [0.21477, 0.0073, 1.03905], // 425 nm
    [0.2839, 0.0116, 1.3856], // 430 nm
    [0.3285, 0.01684, 1.62296], // 435 nm
    [0.34828, 0.023, 1.74706], // 440 nm
    [0.34806, 0.0298, 1.7826], // 445 nm
    [0.3362, 0.038, 1.77211], // 450 nm
    [0.3187, 0.048, 1.7441], // 455 nm
    [0.2908, 0.06, 1.6692], // 460 nm
    [0.2511, 0.0739, 1.5281], // 465 nm
    [0.19536, 0.09098, 1.28764], // 470 nm
    [0.1421, 0.1126, 1.0419], // 475 nm
    [0.09564, 0.13902, 0.8129501], // 480 nm
    [0.05795001, 0.1693, 0.6162], // 485 nm
    [0.03201, 0.20802, 0.46518], // 490 nm
    [0.0147, 0.2586, 0.3533], // 495 nm
    [0.0049, 0.323, 0.272], // 500 nm
    [0.0024, 0.4073, 0.2123], // 505 nm
    [0.0093, 0.503, 0.1582], // 510 nm
    [0.0291, 0.6082, 0.1117], // 515 nm
    [0.06327, 0.71, 0.07824999], // 520 nm
    [0.1096, 0.7932, 0.05725001], // 525 nm
    [0.1655, 0.862, 0.04216], // 530 nm
    [0.2257499, 0.9148501, 0.02984], // 535 nm
    [0.2904, 0.954, 0.0203], // 540 nm
    [0.3597, 0.9803, 0.0134], // 545 nm
    [0.4334499, 0.9949501, 0.008749999], // 550 nm
    [0.5120501, 1.0, 0.005749999], // 555 nm
    [0.5945, 0.995, 0.0039], // 560 nm
    [0.6784, 0.9786, 0.002749999], // 565 nm
    [0.7621, 0.952, 0.0021], // 570 nm
    [0.8425, 0.9154, 0.0018], // 575 nm
    [0.9163, 0.87, 0.001650001], // 580 nm
    [0.9786, 0.8163, 0.0014], // 585 nm
    [1.0263, 0.757, 0.0011], // 590 nm
    [1.0567, 0.6949, 0.001], // 595 nm
    [1.0622, 0.631, 0.0008], // 600 nm
    [1.0456, 0.5668, 0.0006], // 605 nm
    [1.0026, 0.503, 0.00034], // 610 nm
    [0.9384, 0.4412, 0.00024], // 615 nm
    [0.8544499, 0.381, 0.00019], // 620 nm
    [0.7514, 0.321, 0.0001], // 625 nm
    [0.6424, 0.265, 4.999999e-05], // 630 nm
    [0.5419, 0.217, 3e-05], // 635 nm
    [0.4479, 0.175, 2e-05], // 640 nm
    [0.3608, 0.1382, 1e-05], // 645 nm
    [0.2835, 0.107, 0.0], // 650 nm
    [0.2187, 0.0816, 0.0], // 655 nm
    [0.1649, 0.061, 0.0], // 660 nm
    [0.1212, 0.04458, 0.0], // 665 nm
    [0.0874, 0.032, 0.0], // 670 nm
    [0.0636, 0.0232, 0.0], // 675 nm
    [0.04677, 0.017, 0.0], // 680 nm
    [0.0329, 0.01192, 0.0], // 685 nm
    [0.0227, 0.00821, 0.0], // 690 nm
    [0.01584, 0.005723, 0.0], // 695 nm
    [0.01135916, 0.004102, 0.0], // 700 nm
    [0.008110916, 0.002929, 0.0], // 705 nm
    [0.005790346, 0.002091, 0.0], // 710 nm
    [0.004109457, 0.001484, 0.0], // 715 nm
    [0.002899327, 0.001047, 0.0], // 720 nm
    [0.00204919, 0.00074, 0.0], // 725 nm
    [0.001439971, 0.00052, 0.0], // 730 nm
    [0.0009999493, 0.0003611, 0.0], // 735 nm
    [0.0006900786, 0.0002492, 0.0], // 740 nm
    [0.0004760213, 0.0001719, 0.0], // 745 nm
    [0.0003323011, 0.00012, 0.0], // 750 nm
    [0.0002348261, 8.48e-05, 0.0], // 755 nm
    [0.0001661505, 6e-05, 0.0], // 760 nm
    [0.000117413, 4.24e-05, 0.0], // 765 nm
    [8.307527e-05, 3e-05, 0.0], // 770 nm
    [5.870652e-05, 2.12e-05, 0.0], // 775 nm
    [4.150994e-05, 1.499e-05, 0.0], // 780 nm
    [2.935326e-05, 1.06e-05, 0.0], // 785 nm
    [2.067383e-05, 7.4657e-06, 0.0], // 790 nm
    [1.455977e-05, 5.2578e-06, 0.0], // 795 nm
    [1.025398e-05, 3.7029e-06, 0.0], // 800 nm
    [7.221456e-06, 2.6078e-06, 0.0], // 805 nm
    [5.085868e-06, 1.8366e-06, 0.0], // 810 nm
    [3.581652e-06, 1.2934e-06, 0.0], // 815 nm
    [2.522525e-06, 9.1093e-07, 0.0], // 820 nm
    [1.776509e-06, 6.4153e-07, 0.0], // 825 nm
    [1.251141e-06, 4.5181e-07, 0.0], // 830 nm
];

/// CIE standard illuminant D65, relative spectral power (100 at 560 nm), every 5 nm from
/// [`CIE_MIN`] to [`CIE_MAX`].
#[rustfmt::skip]
const CIE_D65: [f32; CIE_SAMPLES] = [
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015,
    82.7549, 87.1204, 91.486, 92.4589, 93.4318, 90.057, 86.6823, 95.7736,
    104.865, 110.936, 117.008, 117.41, 117.812, 116.336, 114.861, 115.392,
    115.923, 112.367, 108.811, 109.082, 109.354, 108.578, 107.802, 106.296,
    104.79, 106.239, 107.689, 106.047, 104.405, 104.225, 104.046, 102.023,
    100.0, 98.1671, 96.3342, 96.0611, 95.788, 92.2368, 88.6856, 89.3459,
    90.0062, 89.8026, 89.5991, 88.6489, 87.6987, 85.4936, 83.2886, 83.4939,
    83.6992, 81.863, 80.0268, 80.1207, 80.2146, 81.2462, 82.2778, 80.281,
    78.2842, 74.0027, 69.7213, 70.6652, 71.6091, 72.979, 74.349, 67.9765,
    61.604, 65.7448, 69.8856, 72.4863, 75.087, 69.3398, 63.5927, 55.0054,
    46.4182, 56.6118, 66.8054, 65.0941, 63.3828, 63.8434, 64.304, 61.8779,
    59.4519, 55.7054, 51.959, 54.6998, 57.4406, 58.8765, 60.3125,
];

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Rgb, b: Rgb, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol
    }

    #[test]
    fn constant_reflectance_of_one_is_white() {
        let white = spectrum_list_to_srgb(&[(360.0, 1.0), (830.0, 1.0)], SpectrumKind::Reflectance);
        // Mitsuba's own 1000-step integration gives 0.99898, 0.99887, 0.99880: match it exactly,
        // and (1, 1, 1) to within that discretisation error.
        assert!(
            close(white, Rgb::new(0.998_983, 0.998_872, 0.998_802), 1e-5),
            "{white}"
        );
        assert!(close(white, Rgb::ONE, 1.5e-3), "{white}");
        // Over the visible range only, as many scene files write it (Mitsuba: 0.9953, 0.9998, 0.9949).
        let vis = spectrum_list_to_srgb(&[(400.0, 1.0), (700.0, 1.0)], SpectrumKind::Reflectance);
        assert!(
            close(vis, Rgb::new(0.995_342, 0.999_756, 0.994_909), 2e-4),
            "{vis}"
        );
    }

    #[test]
    fn matches_mitsuba_reference_values() {
        // Values printed by Mitsuba 3.9.1 scalar_rgb for the same XML spectra.
        let refl = [(400.0, 0.343), (500.0, 0.7), (600.0, 0.74), (700.0, 0.737)];
        let c = spectrum_list_to_srgb(&refl, SpectrumKind::Reflectance);
        assert!(
            close(c, Rgb::new(0.735_392, 0.729_912, 0.509_705), 2e-4),
            "{c}"
        );
        let light = [(400.0, 0.0), (500.0, 8.0), (600.0, 15.6), (700.0, 18.4)];
        let c = spectrum_list_to_srgb(&light, SpectrumKind::Emission);
        assert!(close(c, Rgb::new(20.7108, 10.8546, 2.77115), 5e-3), "{c}");
        // Out-of-gamut reflectance is clamped to [0, 1].
        let c = spectrum_list_to_srgb(&[(500.0, 0.3), (600.0, 0.8)], SpectrumKind::Reflectance);
        assert!(close(c, Rgb::new(0.260_283, 0.529_292, 0.0), 2e-4), "{c}");
        let c = uniform_spectrum_to_srgb(3.0, SpectrumKind::Emission);
        assert!(close(c, Rgb::new(3.61438, 2.84487, 2.72675), 1e-3), "{c}");
        assert_eq!(
            uniform_spectrum_to_srgb(0.3, SpectrumKind::Reflectance),
            Rgb::splat(0.3)
        );
    }

    #[test]
    fn d65_has_unit_luminance_and_tables_are_sane() {
        let mut y = 0.0;
        let n = 4700;
        for i in 0..n {
            let w = CIE_MIN + (i as f64 + 0.5) * (CIE_MAX - CIE_MIN) / n as f64;
            y += cie1931_xyz(w)[1] * cie_d65(w) * (CIE_MAX - CIE_MIN) / n as f64;
        }
        assert!((y * CIE_Y_NORMALIZATION - 1.0).abs() < 2e-3, "{y}");
        assert_eq!(cie1931_xyz(555.0)[1], 1.0);
        assert_eq!(cie1931_xyz(300.0), [0.0; 3]);
        assert_eq!(cie_d65(900.0), 0.0);
    }
}
