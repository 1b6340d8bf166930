//! The training losses: paper Eq. 8 (relative L1 on log-tonemapped colours, the default), the
//! evaluation metric relMSE, and relMSE for noisy references, selectable per training run.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use crate::metrics::relmse;

/// What a training step minimises (`loss` in the train TOML).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Loss {
    /// Paper Eq. 8 (docs/method.md §5.5): relative L1 of log(1 + x); robust to the outliers of noisy
    /// references, the loss every run starts with.
    #[default]
    RelativeLogL1,
    /// The evaluation metric itself, relMSE (docs/method.md §5.6): squares the error, so it weighs the few
    /// pixels with large errors (caustic and shadow edges) that dominate the evaluated figure
    /// far more than Eq. 8 does. Meant for fine-tuning a network trained with Eq. 8.
    Relmse,
    /// relMSE for noisy references (Noise2Noise): (ŷ − y)² / (mean_c(ŷ)² + 0.01) with the
    /// denominator taken from the prediction and held constant (no gradient through it). Its
    /// gradient is linear in the reference, so over references with independent zero-mean
    /// noise it equals, in expectation, the gradient against the noise-free one: training on
    /// cheap noisy targets (the `large` dataset's) aims at the same output. Relmse's
    /// denominator and Eq. 8's logarithm and absolute value are not linear in the reference.
    NoisyRelmse,
}

impl Loss {
    /// The loss of a `[B, 3, H, W]` prediction (clamped at zero first) against its reference,
    /// as a one-element tensor.
    pub fn evaluate(self, prediction: Tensor<4>, reference: Tensor<4>) -> Tensor<1> {
        match self {
            Loss::RelativeLogL1 => relative_log_l1(prediction, reference),
            Loss::Relmse => relmse(prediction.clamp_min(0.0), reference),
            Loss::NoisyRelmse => noisy_relmse(prediction, reference),
        }
    }

    /// Whether this is the default loss (for serialising only what differs).
    pub fn is_default(&self) -> bool {
        *self == Loss::default()
    }
}

/// [`Loss::NoisyRelmse`]: mean of (ŷ − y)² / (mean_c(ŷ)² + 0.01), ŷ clamped at zero, the
/// denominator detached. `[B, 3, H, W]` in, one element out.
pub fn noisy_relmse(prediction: Tensor<4>, reference: Tensor<4>) -> Tensor<1> {
    let prediction = prediction.clamp_min(0.0);
    let denominator = prediction
        .clone()
        .detach()
        .mean_dim(1)
        .square()
        .add_scalar(0.01);
    ((prediction - reference).square() / denominator).mean()
}

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

    /// The gradient with respect to the prediction against two references is twice the
    /// gradient against their mean: noise in the reference averages out of the gradient.
    #[test]
    fn noisy_relmse_gradient_is_linear_in_the_reference() {
        let device = Device::flex().autodiff();
        let shape = [1, 3, 2, 1];
        let p = vec![0.5f32, 2.0, 0.1, 0.3, 1.5, 0.0];
        let r1 = vec![0.9f32, 1.0, 0.0, 0.7, 3.0, 0.2];
        let r2 = vec![0.1f32, 2.6, 0.4, 0.1, 0.4, 0.0];
        let mean: Vec<f32> = r1.iter().zip(&r2).map(|(a, b)| 0.5 * (a + b)).collect();
        let grad = |loss: Loss, refs: &[&Vec<f32>]| -> Vec<f32> {
            let x =
                Tensor::<4>::from_data(TensorData::new(p.clone(), shape), &device).require_grad();
            let mut total = None;
            for r in refs {
                let r = Tensor::<4>::from_data(TensorData::new((*r).clone(), shape), &device);
                let l = loss.evaluate(x.clone(), r);
                total = Some(match total {
                    None => l,
                    Some(t) => t + l,
                });
            }
            let grads = total.unwrap().backward();
            x.grad(&grads)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap()
        };
        let pair = grad(Loss::NoisyRelmse, &[&r1, &r2]);
        let twice: Vec<f32> = grad(Loss::NoisyRelmse, &[&mean])
            .iter()
            .map(|g| 2.0 * g)
            .collect();
        for (a, b) in pair.iter().zip(&twice) {
            assert!((a - b).abs() < 1e-5, "{pair:?} vs {twice:?}");
        }
        // relMSE's reference denominator breaks it (the property can fail).
        let pair = grad(Loss::Relmse, &[&r1, &r2]);
        let twice: Vec<f32> = grad(Loss::Relmse, &[&mean])
            .iter()
            .map(|g| 2.0 * g)
            .collect();
        assert!(pair.iter().zip(&twice).any(|(a, b)| (a - b).abs() > 1e-3));
    }

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
    fn relmse_loss_is_the_metric_of_the_clamped_prediction() {
        let device = Device::flex();
        // Pixel A: reference (1, 2, 3), mean 2, denominator 4.01; prediction (2, 2, −1) clamps
        // to (2, 2, 0): errors 1, 0, 9 → 10 / 4.01. Pixel B: reference 0, denominator 0.01;
        // prediction (0.1, 0, 0) → 0.01 / 0.01 = 1. Mean over 6 entries.
        let reference = Tensor::<4>::from_data(
            TensorData::new(vec![1.0, 0.0, 2.0, 0.0, 3.0, 0.0], [1, 3, 1, 2]),
            &device,
        );
        let prediction = Tensor::<4>::from_data(
            TensorData::new(vec![2.0, 0.1, 2.0, 0.0, -1.0, 0.0], [1, 3, 1, 2]),
            &device,
        );
        let loss = Loss::Relmse
            .evaluate(prediction.clone(), reference.clone())
            .into_scalar::<f32>();
        let expected = (10.0 / 4.01 + 1.0) / 6.0;
        assert!((loss - expected).abs() < 1e-6, "{loss} vs {expected}");
        let default = Loss::default().evaluate(prediction.clone(), reference.clone());
        let eq8 = relative_log_l1(prediction, reference);
        assert_eq!(default.into_scalar::<f32>(), eq8.into_scalar::<f32>());
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
