//! Network-level tests: parameter count, the reconstruction's clamp, weight files saved and
//! loaded, backend agreement.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use model::combine::reconstruct;
use model::synthetic::{
    conv_bias as bias, max_relative_difference, synthetic_reconstruction, synthetic_sample,
};
use model::weights::{load_burnpack, save_burnpack};
use model::{ModelConfig, Preset};

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("model-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn paper_preset_has_about_2_4_million_parameters() {
    let config = ModelConfig::preset(Preset::Paper);
    let net = config.init(0, &Device::flex());
    let n = net.num_params();
    println!("paper preset: {n} parameters");
    // 27·25·50+50 + 8·(50·25·50+50) + 50·25·1444+1444 = 2 340 644.
    assert_eq!(n, 2_340_644);
    assert_eq!(config.out_channels(), 1444);
    assert_eq!(net.hidden.len() + 1, 10);
    // Zero biases, Glorot-uniform weights within ±sqrt(6 / (fan_in + fan_out)).
    let limit = (6.0f32 / ((27 + 50) * 25) as f32).sqrt();
    let w = net.hidden[0]
        .weight
        .val()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert!(w.iter().all(|v| v.abs() <= limit));
    assert!(w.iter().any(|v| v.abs() > 0.9 * limit));
    assert!(bias(&net.output).iter().all(|&v| v == 0.0));
}

/// Eq. 6 goes negative next to a spike that only the correlated levels hold (ỹ ≡ 0, z̃ = a
/// spike): ŷ_c = Σ w_i (0 + z̃_c − z̃_i) / Σ w_i < 0 around it for any positive weights. The
/// reconstruction without the safeguard is that combination clamped at zero — what the loss
/// trains on (docs/method.md §5.5).
#[test]
fn reconstruction_is_the_combination_clamped_at_zero() {
    let device = Device::flex();
    let config = ModelConfig {
        guard: 0.0,
        ..ModelConfig::preset(Preset::Tiny)
    };
    let net = config.init(7, &device);
    let (w, h) = (9, 8);
    let s = synthetic_sample(w, h, 0.3, 5);
    let mut levels = vec![0.0f32; 15 * w * h];
    for level in 1..5 {
        for c in 0..3 {
            levels[((level * 3 + c) * h + 4) * w + 4] = 1000.0;
        }
    }
    let f = || {
        Tensor::<4>::from_data(
            TensorData::new(s.packed.features.clone(), [1, 27, h, w]),
            &device,
        )
    };
    let l = || Tensor::<4>::from_data(TensorData::new(levels.clone(), [1, 15, h, w]), &device);
    let raw = model::combine(l(), net.weights(f()), config.window)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let out = reconstruct(&net, &config, f(), l())
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert!(
        raw.iter().filter(|&&v| v < -1.0).count() > 10,
        "the spike must drive Eq. 6 negative around it"
    );
    for (r, o) in raw.iter().zip(&out) {
        assert_eq!(*o, r.max(0.0));
    }
}

#[test]
fn save_then_load_gives_identical_outputs() {
    let device = Device::flex();
    let config = ModelConfig::preset(Preset::Tiny);
    let net = config.init(42, &device);
    let dir = temp_dir("save-load");
    let path = dir.join("model.bpk");
    save_burnpack(&net, &path).unwrap();
    let loaded = load_burnpack(&config, &path, &device).unwrap();
    assert_eq!(
        synthetic_reconstruction(&net, &config, 3, &device),
        synthetic_reconstruction(&loaded, &config, 3, &device)
    );
    // A different config must be refused, not silently half-loaded, naming the file and the
    // tensor whose shape differs.
    let err = load_burnpack(&ModelConfig::preset(Preset::Small), &path, &device)
        .expect_err("tiny weights must not load into the small preset");
    assert!(
        err.contains("model.bpk") && err.contains("ShapeMismatch") && err.contains("hidden.0"),
        "{err}"
    );
}

/// Weights of a deeper network are refused by a config with fewer hidden layers of the same
/// shapes (not loaded with the extra layers dropped), naming the file and the extra tensors.
#[test]
fn weights_with_extra_layers_are_refused() {
    let device = Device::flex();
    let deep = ModelConfig::preset(Preset::Small);
    let dir = temp_dir("extra-layers");
    let path = dir.join("model.bpk");
    save_burnpack(&deep.init(1, &device), &path).unwrap();
    let shallow = ModelConfig {
        hidden_layers: 2,
        ..deep.clone()
    };
    let err = load_burnpack(&shallow, &path, &device)
        .expect_err("5 hidden layers must not load into a network of 2");
    assert!(
        err.contains("model.bpk") && err.contains("hidden.4.weight") && err.contains("2 hidden"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[allow(deprecated)]
fn ndarray_and_flex_agree() {
    let config = ModelConfig::preset(Preset::Tiny);
    let flex = Device::flex();
    let nd = Device::ndarray();
    let a = synthetic_reconstruction(&config.init(9, &flex), &config, 4, &flex);
    let b = synthetic_reconstruction(&config.init(9, &nd), &config, 4, &nd);
    let max_diff = max_relative_difference(&a, &b);
    assert!(max_diff < 1e-4, "flex vs ndarray differ by {max_diff}");
}

/// The U-Net trains: Adam steps through its pooling, upsampling and skips (on a 30×22 patch,
/// sides not multiples of 8) lower the loss of paper Eq. 8 on a synthetic sample, and every
/// hidden layer receives a gradient.
#[test]
fn unet_training_steps_decrease_the_loss() {
    use burn::optim::{AdamConfig, GradientsParams};
    let device = Device::flex().autodiff();
    let config = ModelConfig::preset(Preset::UNet);
    let mut net = config.init(5, &device);
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let (w, h) = (30, 22);
    let s = synthetic_sample(w, h, 0.3, 6);
    let features = || {
        Tensor::<4>::from_data(
            TensorData::new(s.packed.features.clone(), [1, 27, h, w]),
            &device,
        )
    };
    let levels = || {
        Tensor::<4>::from_data(
            TensorData::new(s.packed.levels.clone(), [1, 15, h, w]),
            &device,
        )
    };
    let reference =
        || Tensor::<4>::from_data(TensorData::new(s.reference.clone(), [1, 3, h, w]), &device);
    let mut losses = Vec::new();
    for step in 0..12 {
        let prediction = reconstruct(&net, &config, features(), levels());
        let loss = model::relative_log_l1(prediction, reference());
        let grads = loss.backward();
        losses.push(loss.into_scalar::<f32>());
        if step == 0 {
            for (l, conv) in net.hidden.iter().enumerate() {
                let g = conv
                    .weight
                    .grad(&grads)
                    .expect("a gradient for every layer");
                let g = g.abs().sum().into_scalar::<f32>();
                assert!(g > 0.0, "hidden layer {l} gets no gradient");
            }
        }
        let grads = GradientsParams::from_grads(grads, &net);
        net = optim.step(1e-3, net, grads);
    }
    eprintln!("unet losses: {losses:?}");
    assert!(
        losses[losses.len() - 1] < 0.9 * losses[0],
        "the loss did not fall: {losses:?}"
    );
}
