//! The training loss of paper Eq. 8: relative L1 on log-tonemapped colours.

use burn::tensor::Tensor;

/// L = mean_{c,l} |log(ŷ_{c,l}+1) − log(y_{c,l}+1)| / (ȳ_c + 0.01), ȳ_c = mean_l log(y_{c,l}+1).
///
/// `prediction` and `reference` are `[B, 3, H, W]`; the prediction is clamped at zero first
/// (Eq. 6 can produce small negative values through the difference terms). Returns a
/// one-element tensor.
pub fn relative_log_l1(prediction: Tensor<4>, reference: Tensor<4>) -> Tensor<1> {
    let log_prediction = prediction.clamp_min(0.0).log1p();
    let log_reference = reference.log1p();
    let mean_log_reference = log_reference.clone().mean_dim(1).add_scalar(0.01);
    ((log_prediction - log_reference).abs() / mean_log_reference).mean()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    #[test]
    fn hand_computed_loss() {
        let device = Device::flex();
        // One pixel. Reference (e−1, e−1, e−1): log(y+1) = 1 per channel, ȳ = 1, denominator 1.01.
        // Prediction (e−1, 0, −5): |1−1| + |0−1| + |0−1| (−5 clamps to 0) = 2 → L = 2 / 3 / 1.01.
        let e1 = std::f32::consts::E - 1.0;
        let reference =
            Tensor::<4>::from_data(TensorData::new(vec![e1, e1, e1], [1, 3, 1, 1]), &device);
        let prediction =
            Tensor::<4>::from_data(TensorData::new(vec![e1, 0.0, -5.0], [1, 3, 1, 1]), &device);
        let loss = relative_log_l1(prediction, reference).into_scalar::<f32>();

        assert!((loss - 2.0 / 3.0 / 1.01).abs() < 1e-6, "{loss}");
    }

    #[test]
    fn hand_computed_loss_two_pixels() {
        let device = Device::flex();
        // Pixel A: reference 0 → ȳ = 0, denominator 0.01; prediction (e−1, 0, 0) → |1|/0.01 = 100.
        // Pixel B: exact → 0. L = 100 / 6.
        let e1 = std::f32::consts::E - 1.0;
        let reference = Tensor::<4>::from_data(
            TensorData::new(vec![0.0, 1.0, 0.0, 1.0, 0.0, 1.0], [1, 3, 1, 2]),
            &device,
        );
        let prediction = Tensor::<4>::from_data(
            TensorData::new(vec![e1, 1.0, 0.0, 1.0, 0.0, 1.0], [1, 3, 1, 2]),
            &device,
        );
        let loss: f32 = relative_log_l1(prediction, reference).into_scalar::<f32>();
        assert!((loss - 100.0 / 6.0).abs() < 1e-3, "{loss}");
    }
}
