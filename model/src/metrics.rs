//! Image error metrics: relative MSE (docs/method.md §5.6), on tensors and on host images.

use burn::tensor::Tensor;

/// Relative MSE: mean over pixels and channels of (ŷ − y)² / (mean_l(y)² + 0.01).
///
/// `prediction` and `reference` are `[B, 3, H, W]`; returns a one-element tensor.
pub fn relmse(prediction: Tensor<4>, reference: Tensor<4>) -> Tensor<1> {
    let denominator = reference.clone().mean_dim(1).square().add_scalar(0.01);
    ((prediction - reference).square() / denominator).mean()
}

/// Sum (not mean) of the relative squared errors of planar RGB images (`[3][pixels]` layout),
/// accumulated in f64 in pixel order; divide by `3 · pixels` for the relMSE. Summing lets
/// callers pool several images or tiles into one mean.
pub fn relmse_sum_planar(prediction: &[f32], reference: &[f32]) -> f64 {
    assert_eq!(prediction.len(), reference.len(), "image sizes differ");
    assert_eq!(reference.len() % 3, 0, "planar RGB needs 3 channels");
    let pixels = reference.len() / 3;
    let mut sum = 0.0f64;
    for p in 0..pixels {
        let mean =
            (reference[p] as f64 + reference[pixels + p] as f64 + reference[2 * pixels + p] as f64)
                / 3.0;
        let denominator = mean * mean + 0.01;
        for c in 0..3 {
            let e = prediction[c * pixels + p] as f64 - reference[c * pixels + p] as f64;
            sum += e * e / denominator;
        }
    }
    sum
}

/// Relative MSE of planar RGB images (`[3][pixels]` layout).
pub fn relmse_planar(prediction: &[f32], reference: &[f32]) -> f64 {
    relmse_sum_planar(prediction, reference) / reference.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    #[test]
    fn hand_computed_relmse() {
        // Pixel 0: reference (1, 2, 3), mean 2, denominator 4.01; errors (1, 0, −2) → 5 / 4.01.
        // Pixel 1: reference 0, denominator 0.01; errors (0.1, 0, 0) → 0.01 / 0.01 = 1.
        // relMSE = (5/4.01 + 1) / 6.
        let reference = vec![1.0, 0.0, 2.0, 0.0, 3.0, 0.0];
        let prediction = vec![2.0, 0.1, 2.0, 0.0, 1.0, 0.0];
        let expected = (5.0 / 4.01 + 1.0) / 6.0;
        assert!((relmse_planar(&prediction, &reference) - expected).abs() < 1e-6);
        let device = Device::flex();
        let t = |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [1, 3, 1, 2]), &device);
        let got: f32 = relmse(t(prediction), t(reference)).into_scalar::<f32>();
        assert!((got as f64 - expected).abs() < 1e-5, "{got}");
    }
}
