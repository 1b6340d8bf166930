//! Training-loop tests on synthetic data: the same files on any thread count, exact resume,
//! the learning-rate schedule, wgpu against flex, learning beyond the best input level, and
//! fine-tuning from a smaller network.

use burn::module::Module;
use burn::tensor::Device;
use model::loss::Loss;
use model::synthetic::{
    conv_bias as bias, max_relative_difference, parameters, synthetic_raw_output as raw_output,
    synthetic_reconstruction as forward_values, synthetic_sample,
};
use model::weights::save_burnpack;
use model::{ModelConfig, Preset};
use train::data::PatchDataset;
use train::training::{validate, TrainSettings, Trainer};

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("train-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn tiny_sets() -> (PatchDataset, PatchDataset) {
    let train = (0..3)
        .map(|i| synthetic_sample(32, 32, 0.3, 100 + i))
        .collect();
    let val = vec![synthetic_sample(32, 32, 0.3, 200)];
    (
        PatchDataset::from_samples(train, 16, 8),
        PatchDataset::from_samples(val, 16, 16),
    )
}

/// Settings of the tests' tiny training runs: batch 4, constant `lr`, the default loss.
fn tiny_settings(epochs: usize, lr: f64, seed: u64) -> TrainSettings {
    TrainSettings {
        batch: 4,
        epochs,
        lr,
        lr_end: None,
        seed,
        loss: Loss::default(),
    }
}

#[test]
fn training_writes_the_same_files_on_any_thread_count() {
    // Weights, checkpoint and optimizer state, byte for byte: the parameter ids stored in them
    // are numbered, not drawn, and the safetensors header is sorted (state.json is left out:
    // it records each epoch's seconds).
    let config = ModelConfig::preset(Preset::Tiny);
    let train_in = |threads: usize, dir: &std::path::Path| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let device = Device::flex();
            let (mut train, _) = tiny_sets();
            let mut trainer = Trainer::new(config.clone(), tiny_settings(1, 1e-3, 9), &device);
            trainer.run_epoch(&mut train, None, &mut |_| {}).unwrap();
            trainer.save_checkpoint(&dir.join("checkpoint")).unwrap();
            trainer.save_final(dir).unwrap();
        });
    };
    let (one, two) = (temp_dir("threads-1"), temp_dir("threads-2"));
    train_in(1, &one);
    train_in(2, &two);
    for file in [
        "model.bpk",
        "model.safetensors",
        "model.json",
        "checkpoint/model.bpk",
        "checkpoint/optimizer.bpk",
    ] {
        let a = std::fs::read(one.join(file)).unwrap();
        let b = std::fs::read(two.join(file)).unwrap();
        assert!(a == b, "{file} differs between 1 and 2 threads");
    }
    // The sorted header is still a valid safetensors file with the same tensors.
    let bytes = std::fs::read(one.join("model.safetensors")).unwrap();
    let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + len]).unwrap();
    let tensors = header
        .as_object()
        .unwrap()
        .keys()
        .filter(|k| *k != "__metadata__")
        .count();
    assert_eq!(tensors, 2 * (config.hidden_layers + 1));
    let _ = std::fs::remove_dir_all(&one);
    let _ = std::fs::remove_dir_all(&two);
}

#[test]
fn resume_continues_exactly() {
    let device = Device::flex();
    let config = ModelConfig::preset(Preset::Tiny);
    // With a decaying learning rate: the resumed run must continue the schedule, not restart it.
    let settings = TrainSettings {
        lr_end: Some(1e-4),
        ..tiny_settings(2, 1e-3, 5)
    };
    let (mut train, _) = tiny_sets();
    let mut none = |_| {};

    let mut straight = Trainer::new(config.clone(), settings.clone(), &device);
    straight.run_epoch(&mut train, None, &mut none).unwrap();
    straight.run_epoch(&mut train, None, &mut none).unwrap();

    let dir = temp_dir("resume");
    let mut first = Trainer::new(config.clone(), settings.clone(), &device);
    first.run_epoch(&mut train, None, &mut none).unwrap();
    first.save_checkpoint(&dir).unwrap();
    drop(first);
    // A decay spans the run's epochs: resuming with another epoch count is refused.
    let longer = TrainSettings {
        epochs: 3,
        ..settings.clone()
    };
    let err = Trainer::resume(&dir, longer, &device)
        .err()
        .expect("another epoch count under a decay must be refused");
    assert!(
        err.contains("state.json") && err.contains("epochs 2 (checkpoint) vs 3 (config"),
        "{err}"
    );
    // So is another loss: the checkpoint's steps minimised a different objective.
    let other_loss = TrainSettings {
        loss: Loss::Relmse,
        ..settings.clone()
    };
    let err = Trainer::resume(&dir, other_loss, &device)
        .err()
        .expect("another loss must be refused");
    assert!(
        err.contains("state.json")
            && err.contains("loss relative-log-l1 (checkpoint) vs relmse (config)"),
        "{err}"
    );
    // Only the settings that differ are named.
    assert!(!err.contains("epochs") && !err.contains("lr"), "{err}");
    let mut resumed = Trainer::resume(&dir, settings, &device).unwrap();
    assert_eq!(resumed.epochs_done, 1);
    resumed.run_epoch(&mut train, None, &mut none).unwrap();

    let a = parameters(&straight.model);
    let b = parameters(&resumed.model);
    assert_eq!(a.len(), b.len());
    let max_diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert_eq!(
        max_diff, 0.0,
        "resumed weights differ from the uninterrupted run"
    );
    assert_eq!(
        straight.history[1].train_loss,
        resumed.history[1].train_loss
    );
}

#[test]
fn cosine_decay_runs_from_lr_to_lr_end() {
    let constant = tiny_settings(2, 1e-3, 1);
    assert_eq!(constant.lr_at(0, 10), 1e-3);
    assert_eq!(constant.lr_at(9, 10), 1e-3);
    let decay = TrainSettings {
        lr_end: Some(1e-5),
        ..constant
    };
    assert_eq!(decay.lr_at(0, 11), 1e-3);
    assert!((decay.lr_at(10, 11) - 1e-5).abs() < 1e-15);
    // Halfway: the mean of the two.
    assert!((decay.lr_at(5, 11) - 0.5 * (1e-3 + 1e-5)).abs() < 1e-15);
    let lrs: Vec<f64> = (0..11).map(|s| decay.lr_at(s, 11)).collect();
    assert!(lrs.windows(2).all(|w| w[1] < w[0]), "{lrs:?}");
    // A one-step run uses `lr`.
    assert_eq!(decay.lr_at(0, 1), 1e-3);
}

/// The network's forward pass and one training epoch (Adam steps, then validation) give the
/// same numbers on wgpu as on flex. Ignored (visibly) without the `wgpu` feature; with it, it
/// runs wherever an adapter exists — a GPU, or Mesa's lavapipe on a CPU-only machine
/// (`apt-get install mesa-vulkan-drivers`) — and fails where none does: whoever enables the GPU
/// tests wants them run, not skipped.
#[test]
#[cfg_attr(
    not(feature = "wgpu"),
    ignore = "needs --features model/wgpu and a GPU adapter"
)]
fn wgpu_and_flex_agree_when_an_adapter_exists() {
    let gpu = model::backend::Backend::Wgpu.device().unwrap_or_else(|e| {
        panic!(
            "the wgpu test needs `--features model/wgpu` and a graphics adapter (a GPU, or \
             Mesa's lavapipe: apt-get install mesa-vulkan-drivers): {e}"
        )
    });
    if let Some(note) = model::backend::Backend::Wgpu.adapter_note(&gpu) {
        eprintln!("{note}");
    }
    let config = ModelConfig::preset(Preset::Tiny);
    let flex = Device::flex();
    let a = forward_values(&config.init(9, &flex), &config, 4, &flex);
    let b = forward_values(&config.init(9, &gpu), &config, 4, &gpu);
    let forward = max_relative_difference(&a, &b);
    assert!(
        forward < 1e-4,
        "flex vs wgpu forward pass differs by {forward}"
    );

    let mut none = |_| {};
    let mut epoch_on = |device: &Device| {
        let (mut train, mut val) = tiny_sets();
        let mut trainer = Trainer::new(config.clone(), tiny_settings(1, 1e-3, 5), device);
        let report = trainer
            .run_epoch(&mut train, Some(&mut val), &mut none)
            .unwrap();
        let relmse = report.validation.expect("validated").output;
        (parameters(&trainer.model), report.train_loss, relmse)
    };
    let (weights_flex, loss_flex, relmse_flex) = epoch_on(&flex);
    let (weights_gpu, loss_gpu, relmse_gpu) = epoch_on(&gpu);
    let weights = max_relative_difference(&weights_flex, &weights_gpu);
    assert!(
        weights < 1e-4,
        "weights after one epoch differ by {weights}"
    );
    let loss = ((loss_flex - loss_gpu) / loss_flex).abs();
    assert!(
        loss < 1e-4,
        "train loss {loss_flex} (flex) vs {loss_gpu} (wgpu)"
    );
    let relmse = ((relmse_flex - relmse_gpu) / relmse_flex).abs();
    assert!(
        relmse < 1e-4,
        "val relMSE {relmse_flex} (flex) vs {relmse_gpu} (wgpu)"
    );
}

/// Trains the tiny preset 6 epochs on the synthetic sets minimising `loss` and checks that the
/// validation relMSE falls clearly, to clearly below the best single input level. The learner
/// is checked on Eq. 6 alone (guard 0): the guard pulls the output towards the smoothest level
/// where the network departs from it by less than the noise the bundle's variances claim, and
/// the synthetic levels' bias and variances are not a renderer's (here the smoothest level is
/// not the best one, and the guarded output stays near it).
fn training_beats_the_best_input_level_with(loss: Loss) {
    let device = Device::flex();
    let config = ModelConfig {
        guard: 0.0,
        ..ModelConfig::preset(Preset::Tiny)
    };
    let settings = TrainSettings {
        loss,
        ..tiny_settings(6, 3e-3, 1)
    };
    let (mut train, mut val) = tiny_sets();
    let mut trainer = Trainer::new(config.clone(), settings.clone(), &device);
    let before = validate(&trainer.model.valid(), &config, &mut val, 4, &device).unwrap();
    let mut none = |_| {};
    for _ in 0..settings.epochs {
        let r = trainer
            .run_epoch(&mut train, Some(&mut val), &mut none)
            .unwrap();
        let v = r.validation.unwrap();
        println!(
            "epoch {}: loss {:.4} val {:.5} best level {:?}",
            r.epoch,
            r.train_loss,
            v.output,
            v.best_level()
        );
    }
    let after = trainer.history.last().unwrap().validation.clone().unwrap();
    let (best, best_value) = after.best_level();
    println!(
        "before {:.5}, after {:.5}, best input level z{best} {:.5}",
        before.output, after.output, best_value
    );
    // The untrained network already blurs the levels (≈ 0.96× the best level on this data), so
    // ask for a clear margin on both: training must do the work, not the initial averaging.
    assert!(
        after.output < 0.8 * before.output,
        "training did not reduce the validation relMSE enough: {} -> {}",
        before.output,
        after.output
    );
    assert!(
        after.output < 0.8 * best_value,
        "output {} not clearly below the best level {}",
        after.output,
        best_value
    );
}

#[test]
fn training_beats_the_best_input_level() {
    training_beats_the_best_input_level_with(Loss::RelativeLogL1);
}

#[test]
fn training_on_relmse_beats_the_best_input_level() {
    training_beats_the_best_input_level_with(Loss::Relmse);
}

/// A tiny network trained one epoch on [`tiny_sets`] (so its biases are not zero, as in a
/// trained model) and saved as the model directory `name`: its config, the network, the
/// directory and the training set.
fn trained_tiny_model(
    name: &str,
    settings: &TrainSettings,
) -> (
    ModelConfig,
    model::Network,
    std::path::PathBuf,
    PatchDataset,
) {
    let device = Device::flex();
    let config = ModelConfig::preset(Preset::Tiny);
    let (mut train, _) = tiny_sets();
    let mut trainer = Trainer::new(config.clone(), settings.clone(), &device);
    trainer.run_epoch(&mut train, None, &mut |_| {}).unwrap();
    let net = trainer.model.valid();
    assert!(bias(&net.hidden[0]).iter().any(|&v| v != 0.0));
    let dir = temp_dir(name);
    save_burnpack(&net, &dir.join("model.bpk")).unwrap();
    std::fs::write(
        dir.join("model.json"),
        serde_json::to_string(&config).unwrap(),
    )
    .unwrap();
    (config, net, dir, train)
}

/// A trained network grown into a wider and deeper architecture computes the same output (so
/// fine-tuning starts where the small network stands), and training then moves the weights
/// that were zero — the new filters are used. Incompatible architectures are refused by name.
#[test]
fn grown_network_computes_the_same_function_and_trains() {
    let device = Device::flex();
    let settings = tiny_settings(1, 3e-3, 1);
    let (small, net, dir, mut train) = trained_tiny_model("grow", &settings);
    let mut none = |_| {};

    let big = ModelConfig {
        hidden_layers: small.hidden_layers + 2,
        filters: small.filters + 8,
        ..small.clone()
    };
    let grown = big.grow(&small, &net, 9, &device).unwrap();
    assert_eq!(grown.hidden.len(), big.hidden_layers);
    assert_eq!(grown.num_params(), big.init(0, &device).num_params());
    let (a, b) = (raw_output(&net, &device), raw_output(&grown, &device));
    let scale = a.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    let worst = a
        .iter()
        .zip(&b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(
        worst <= 1e-5 * scale,
        "grown output differs by {worst} (scale {scale})"
    );

    // Through `init` of a training config: a model directory with the small network.
    let mut tuned = Trainer::from_weights(big.clone(), settings.clone(), &dir, &device).unwrap();
    assert_eq!(
        raw_output(&tuned.model.valid(), &device),
        raw_output(
            &big.grow(&small, &net, settings.seed, &device).unwrap(),
            &device
        )
    );
    tuned.run_epoch(&mut train, None, &mut none).unwrap();
    // The last layer's weights from the new channels started at zero.
    let w = tuned
        .model
        .output
        .weight
        .val()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let area = big.kernel * big.kernel;
    let from_new = (0..big.out_channels())
        .flat_map(|o| (small.filters..big.filters).map(move |i| (o * big.filters + i) * area))
        .flat_map(|start| start..start + area)
        .filter(|&i| w[i] != 0.0)
        .count();
    assert!(from_new > 0, "the new channels' output weights never moved");

    // Another guard is not another architecture: the same weights, the config's guard.
    let other_guard = ModelConfig {
        guard: small.guard + 4.0,
        guard_target_noise: small.guard_target_noise * 4.0,
        ..small.clone()
    };
    let reguarded = Trainer::from_weights(other_guard.clone(), settings.clone(), &dir, &device)
        .expect("a different guard must start from the same weights");
    assert_eq!(reguarded.config, other_guard);
    assert_eq!(
        raw_output(&reguarded.model.valid(), &device),
        raw_output(&net, &device)
    );

    let narrower_window = ModelConfig {
        window: small.window - 2,
        ..big.clone()
    };
    let err = Trainer::from_weights(narrower_window, settings.clone(), &dir, &device)
        .err()
        .expect("a narrower window must be refused");
    assert!(err.contains("window"), "{err}");
    let softmax_wider = ModelConfig {
        window: small.window + 2,
        weighting: model::Weighting::Softmax,
        ..big.clone()
    };
    assert!(softmax_wider.growth_obstacle(&small).is_some());
    let narrower = ModelConfig {
        filters: small.filters - 1,
        ..small.clone()
    };
    let err = Trainer::from_weights(narrower, settings, &dir, &device)
        .err()
        .expect("a narrower network must be refused");
    assert!(err.contains("do not fit"), "{err}");
}

/// Fine-tuning with extra feature planes from weights trained without them: the run starts
/// from the trained network's function (its raw output on the same bundle is unchanged), an
/// epoch on samples packed with the planes moves the first convolution's weights from them,
/// and in-memory samples packed without them are not fed to it.
#[test]
fn extra_features_fine_tune_from_weights_without_them() {
    use model::features::{pack_with, ExtraFeature};
    use model::sample::Sample;
    use model::synthetic::synthetic_bundle;
    let device = Device::flex();
    let settings = tiny_settings(1, 3e-3, 1);
    let (plain, net, dir, _) = trained_tiny_model("extra", &settings);

    let wide = plain
        .clone()
        .with_extra_features(vec![ExtraFeature::Disagreement, ExtraFeature::Passes]);
    let mut tuned = Trainer::from_weights(wide.clone(), settings.clone(), &dir, &device).unwrap();
    let packed_sample = |config: &ModelConfig, seed: u64| {
        let (mut bundle, reference) = synthetic_bundle(32, 32, 0.3, seed);
        bundle.meta.passes = 32;
        Sample {
            packed: pack_with(&bundle, &config.packing()).unwrap(),
            reference: model::features::planar_reference(&reference, 32, 32).unwrap(),
        }
    };
    let raw = |network: &model::Network, config: &ModelConfig| -> Vec<f32> {
        let s = packed_sample(config, 4);
        let f = burn::tensor::Tensor::<4>::from_data(
            burn::tensor::TensorData::new(s.packed.features, [1, config.in_channels, 32, 32]),
            &device,
        );
        network.forward(f).into_data().try_to_vec::<f32>().unwrap()
    };
    let d = max_relative_difference(&raw(&net, &plain), &raw(&tuned.model.valid(), &wide));
    assert!(d <= 1e-5, "the widened network starts {d} away");

    let samples = (0..3).map(|i| packed_sample(&wide, 100 + i)).collect();
    let mut train_wide = PatchDataset::from_samples(samples, 16, 8);
    tuned.run_epoch(&mut train_wide, None, &mut |_| {}).unwrap();
    let first = tuned.model.hidden[0]
        .weight
        .val()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let (cin, area) = (wide.in_channels, wide.kernel * wide.kernel);
    let moved = (0..wide.filters)
        .flat_map(|o| (plain.in_channels..cin).map(move |i| (o * cin + i) * area))
        .flat_map(|start| start..start + area)
        .filter(|&i| first[i] != 0.0)
        .count();
    assert!(moved > 0, "the new planes' weights never moved");

    // Samples packed without the planes cannot feed the wider network.
    let refused = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let (mut old, _) = tiny_sets();
        let _ = tuned.run_epoch(&mut old, None, &mut |_| {});
    }));
    assert!(refused.is_err());

    // Weights that read the planes cannot start a config that forgot them: the error says
    // which to list.
    let wide_dir = temp_dir("extra-wide");
    save_burnpack(&tuned.model.valid(), &wide_dir.join("model.bpk")).unwrap();
    std::fs::write(
        wide_dir.join("model.json"),
        serde_json::to_string(&wide).unwrap(),
    )
    .unwrap();
    let err = Trainer::from_weights(plain.clone(), settings.clone(), &wide_dir, &device)
        .err()
        .expect("a config without the model's planes must be refused");
    assert!(
        err.contains(r#"give the config extra_features = ["disagreement","passes"]"#),
        "{err}"
    );
    let shorter = plain.with_extra_features(vec![ExtraFeature::Disagreement]);
    let err = Trainer::from_weights(shorter, settings, &wide_dir, &device)
        .err()
        .expect("a config with fewer planes than the model must be refused");
    assert!(
        err.contains(r#"the config lists ["disagreement"]"#),
        "{err}"
    );
}

/// Widening the combination window keeps every old window entry's raw output and starts the
/// new outer entries at the small positive `NEW_WINDOW_ENTRY`, so the reconstruction barely
/// moves.
#[test]
fn wider_window_keeps_the_old_entries() {
    let device = Device::flex();
    let small = ModelConfig::preset(Preset::Tiny);
    let mut trainer = Trainer::new(small.clone(), tiny_settings(1, 3e-3, 2), &device);
    let (mut train, _) = tiny_sets();
    trainer.run_epoch(&mut train, None, &mut |_| {}).unwrap();
    let net = trainer.model.valid();
    let wide = ModelConfig {
        window: small.window + 4,
        ..small.clone()
    };
    assert!(wide.growth_obstacle(&small).is_none());
    let grown = wide.grow(&small, &net, 3, &device).unwrap();
    let (old, new) = (raw_output(&net, &device), raw_output(&grown, &device));
    let pixels = 12 * 10;
    let (w_old, w_new) = (small.window, wide.window);
    assert_eq!(new.len(), wide.out_channels() * pixels);
    for pair in 0..wide.pairs() {
        for row in 0..w_new {
            for col in 0..w_new {
                let o = (pair * w_new + row) * w_new + col;
                let got = &new[o * pixels..(o + 1) * pixels];
                let (r, c) = (row as i64 - 2, col as i64 - 2);
                if (0..w_old as i64).contains(&r) && (0..w_old as i64).contains(&c) {
                    let old_o = (pair * w_old + r as usize) * w_old + c as usize;
                    let want = &old[old_o * pixels..(old_o + 1) * pixels];
                    for (g, w) in got.iter().zip(want) {
                        assert!(
                            (g - w).abs() <= 1e-5 * (1.0 + w.abs()),
                            "entry {o}: {g} vs {w}"
                        );
                    }
                } else {
                    assert!(
                        got.iter().all(|&g| g == model::NEW_WINDOW_ENTRY),
                        "entry {o}"
                    );
                }
            }
        }
    }
    // The reconstructions differ by the new entries' ≈ 1e-3 weights only.
    let a = forward_values(&net, &small, 3, &device);
    let b = forward_values(&grown, &wide, 3, &device);
    let scale = a.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(&b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    println!("wider window: largest change {worst} (scale {scale})");
    assert!(
        worst <= 0.05 * scale,
        "largest change {worst}, scale {scale}"
    );
}
