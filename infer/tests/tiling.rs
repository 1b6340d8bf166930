//! Tiled reconstruction equals the untiled one; model directories round-trip; the `infer`
//! binary renders and reconstructs a scene by passes or by time, and reports bad input with the
//! file name and a non-zero exit.

use std::path::{Path, PathBuf};
use std::process::Command;

use burn::tensor::Device;
use infer::{reconstruct_tiled, Engine};
use model::features::pack;
use model::model_dir::TrainedModel;
use model::synthetic::{synthetic_bundle, with_biases, with_distinct_biases};
use model::weights::save_burnpack;
use model::{ModelConfig, Network, Preset, Weighting};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("infer-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The bias values of every convolution of `network`, hidden layers first.
fn biases(network: &Network) -> Vec<Vec<f32>> {
    network
        .hidden
        .iter()
        .chain(std::iter::once(&network.output))
        .map(|conv| {
            let bias = conv.bias.as_ref().expect("convolutions have a bias");
            bias.val().into_data().try_to_vec::<f32>().unwrap()
        })
        .collect()
}

/// Panics unless every bias of `network` is non-zero and the values within each layer differ.
fn assert_distinct_non_zero_biases(name: &str, network: &Network) {
    for (layer, mut bias) in biases(network).into_iter().enumerate() {
        assert!(
            bias.iter().all(|&b| b != 0.0),
            "{name}: layer {layer} has a zero bias: {bias:?}"
        );
        let n = bias.len();
        bias.sort_by(f32::total_cmp);
        bias.dedup();
        assert_eq!(bias.len(), n, "{name}: layer {layer} repeats a bias value");
    }
}

/// A network of `preset` and `weighting` with Glorot weights from `seed` and distinct non-zero
/// biases ([`with_distinct_biases`]): the bias path of every engine is exercised.
fn model(preset: Preset, weighting: Weighting, seed: u64) -> TrainedModel {
    let mut config = ModelConfig::preset(preset);
    config.weighting = weighting;
    let network = with_distinct_biases(config.init(seed, &Device::flex()));
    TrainedModel {
        dir: PathBuf::new(),
        config,
        network,
    }
}

/// Largest |a − b| / max(|b|, 1e-3) over all samples.
fn max_relative_difference(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(&x, &y)| ((x - y).abs() / y.abs().max(1e-3)) as f64)
        .fold(0.0, f64::max)
}

/// Tiled reconstruction (ragged tiles, overlapping halos) equals the untiled one, on both
/// engines, for networks with non-zero biases.
#[test]
fn tiled_equals_untiled_on_an_odd_sized_image() {
    // 53×41 with 16-px tiles: 4×3 tiles, ragged last row and column; the small preset's halo
    // (12 px) is most of a tile, so halos overlap several neighbours.
    let (bundle, _) = synthetic_bundle(53, 41, 0.3, 7);
    let packed = pack(&bundle).unwrap();
    let device = Device::flex();
    for (preset, weighting, engine) in [
        (Preset::Small, Weighting::Relu, Engine::Burn),
        (Preset::Tiny, Weighting::Softmax, Engine::Burn),
        (Preset::Small, Weighting::Relu, Engine::Native),
        (Preset::Tiny, Weighting::Softmax, Engine::Native),
        (Preset::UNet, Weighting::Relu, Engine::Burn),
        (Preset::UNet, Weighting::Relu, Engine::Native),
    ] {
        let m = model(preset, weighting, 11);
        assert_distinct_non_zero_biases(&format!("{preset:?}"), &m.network);
        let whole = reconstruct_tiled(&m, &packed, 0, engine, &device, |_, _| {});
        let mut calls = 0;
        let tiled = reconstruct_tiled(&m, &packed, 16, engine, &device, |done, total| {
            calls += 1;
            assert_eq!((done, total), (calls, 12));
        });
        assert_eq!(calls, 12);
        let d = max_relative_difference(&tiled.image, &whole.image);
        assert!(
            d <= 1e-5,
            "{preset:?} {engine:?}: tiled differs from untiled by {d:e} (relative)"
        );
        let d = max_relative_difference(&tiled.shares, &whole.shares);
        assert!(
            d <= 1e-5,
            "{preset:?} {engine:?}: weight shares differ by {d:e}"
        );
        assert!(whole.image.iter().all(|v| v.is_finite()));
        // Shares are a partition of the weight at every pixel.
        let pixels = packed.pixels();
        for p in 0..pixels {
            let s: f32 = (0..4).map(|l| whole.shares[l * pixels + p]).sum();
            assert!((s - 1.0).abs() < 1e-4, "shares sum to {s} at pixel {p}");
        }
    }
}

/// The native engine computes what the Burn engine computes, for every preset, both weightings
/// and a dual network, all with distinct non-zero biases in every layer; the biases change the
/// output far beyond the tolerance, so an engine that skipped them or read them from another
/// layer or channel would fail.
#[test]
fn native_engine_equals_burn() {
    // Every preset, both weightings and a dual (ỹ, z̃3) network, on an image smaller than the
    // paper network's window in one direction (window entries outside the image on both sides).
    let (bundle, _) = synthetic_bundle(31, 17, 0.3, 9);
    let packed = pack(&bundle).unwrap();
    let device = Device::flex();
    let mut dual = model(Preset::Tiny, Weighting::Relu, 4);
    dual.config = dual.config.clone().with_levels(vec![0, 3]);
    dual.network = with_distinct_biases(dual.config.init(4, &device));
    for (name, m) in [
        ("paper", model(Preset::Paper, Weighting::Relu, 1)),
        ("medium", model(Preset::Medium, Weighting::Relu, 6)),
        ("small", model(Preset::Small, Weighting::Relu, 2)),
        ("small softmax", model(Preset::Small, Weighting::Softmax, 2)),
        ("tiny", model(Preset::Tiny, Weighting::Relu, 3)),
        ("tiny softmax", model(Preset::Tiny, Weighting::Softmax, 3)),
        ("unet", model(Preset::UNet, Weighting::Relu, 7)),
        ("unet softmax", model(Preset::UNet, Weighting::Softmax, 7)),
        ("dual", dual),
    ] {
        assert_distinct_non_zero_biases(name, &m.network);
        let burn = reconstruct_tiled(&m, &packed, 0, Engine::Burn, &device, |_, _| {});
        let native = reconstruct_tiled(&m, &packed, 0, Engine::Native, &device, |_, _| {});
        let d = max_relative_difference(&native.image, &burn.image);
        assert!(
            d <= 2e-5,
            "{name}: native differs from Burn by {d:e} (relative)"
        );
        let d = max_abs_difference(&native.shares, &burn.shares);
        assert!(d <= 1e-5, "{name}: weight shares differ by {d:e}");
        // The same network with zero biases reconstructs something else, far outside the
        // tolerance: the comparison above sees the biases.
        let unbiased = TrainedModel {
            dir: PathBuf::new(),
            config: m.config.clone(),
            network: with_biases(m.network.clone(), |_| 0.0),
        };
        assert!(biases(&unbiased.network)
            .iter()
            .flatten()
            .all(|&b| b == 0.0));
        let without = reconstruct_tiled(&unbiased, &packed, 0, Engine::Burn, &device, |_, _| {});
        let image = max_relative_difference(&without.image, &burn.image);
        let shares = max_abs_difference(&without.shares, &burn.shares);
        eprintln!(
            "{name}: biases move the image by {image:e} (relative), the shares by {shares:e}"
        );
        // (A dual network's one share is always 1: only its image can show the biases.)
        let shares_move = m.config.pairs() == 1 || shares > 100.0 * 1e-5;
        assert!(
            image > 100.0 * 2e-5 && shares_move,
            "{name}: the biases move the image by only {image:e} and the shares by {shares:e}: \
             the comparison cannot see them"
        );
    }
}

/// Photon-free layers of a `w`×`h` bundle with no photon-free light at all.
fn no_direct_light(w: usize, h: usize) -> bundle::DirectLight {
    bundle::DirectLight {
        y: bundle::Image::new(w, h, 3),
        z: bundle::Image::new(w, h, 3),
        variance: bundle::Image::new(w, h, 2),
    }
}

/// Adds a light of radiance `light` that path A saw at pixel (x, y): to ỹ and to its
/// photon-free layer (the bundle has the layers).
fn add_light_seen_by_path_a(bundle: &mut bundle::Bundle, x: usize, y: usize, light: f32) {
    for c in 0..3 {
        let v = bundle.levels[0].get(x, y, c);
        bundle.levels[0].set(x, y, c, v + light);
        bundle.direct.as_mut().unwrap().y.set(x, y, c, light);
    }
}

/// The emission split (docs/method.md §5.4): a light that path A saw in one pixel — in ỹ and its
/// `ydirect` layer — stays in that pixel. Against the same bundle without it, the pixel gains
/// the light's weighted share (half, the two subpaths' variances being equal) and no other
/// pixel gains more than 0.2 % of the light (the network sees the light in its features, so
/// neighbouring weights may shift, but only over photon-part values of order one; Eq. 6 on the
/// whole levels hands ≈ 1/121 of it to each pixel of an 11×11 window), on both engines with the
/// guard on and off.
#[test]
fn a_light_seen_in_one_pixel_stays_in_that_pixel() {
    let (w, h) = (23, 19);
    let (mut bundle, _) = synthetic_bundle(w, h, 0.3, 12);
    bundle.direct = Some(no_direct_light(w, h));
    let plain = pack(&bundle).unwrap();
    let (lx, ly) = (11, 9);
    let light = 5000.0f32;
    add_light_seen_by_path_a(&mut bundle, lx, ly, light);
    let lit = pack(&bundle).unwrap();
    let device = Device::flex();
    for guard in [0.0, 4.0] {
        let mut m = model(Preset::Small, Weighting::Relu, 5);
        m.config.guard = guard;
        for engine in [Engine::Native, Engine::Burn] {
            let before = reconstruct_tiled(&m, &plain, 0, engine, &device, |_, _| {});
            let after = reconstruct_tiled(&m, &lit, 0, engine, &device, |_, _| {});
            let pixels = w * h;
            for c in 0..3 {
                for p in 0..pixels {
                    let (b, a) = (before.image[c * pixels + p], after.image[c * pixels + p]);
                    let expected = if p == ly * w + lx { b + light / 2.0 } else { b };
                    assert!(
                        (a - expected).abs() <= 2e-3 * light,
                        "guard {guard} {engine:?}: pixel {p} channel {c}: {a} vs {expected}"
                    );
                }
            }
        }
    }
}

/// Largest |a − b| over all samples.
fn max_abs_difference(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

#[test]
fn native_engine_is_bit_identical_on_any_thread_count() {
    // 45×38 whole, and the U-Net also on 24-px tiles (a tile's steps at every scale).
    let (bundle, _) = synthetic_bundle(45, 38, 0.3, 2);
    let packed = pack(&bundle).unwrap();
    let device = Device::flex();
    for (preset, tile) in [(Preset::Small, 0), (Preset::UNet, 0), (Preset::UNet, 24)] {
        let m = model(preset, Weighting::Relu, 8);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    reconstruct_tiled(&m, &packed, tile, Engine::Native, &device, |_, _| {})
                })
        };
        let one = run(1);
        assert!(one == run(2), "{preset:?} tile {tile}: 1 vs 2 threads");
        assert!(one == run(3), "{preset:?} tile {tile}: 1 vs 3 threads");
    }
}

/// The U-Net's pooling grid is anchored at the image's corner, not at the tile's: on an image
/// whose sides are not multiples of 8 (101×67: grids 101×67, 51×34, 26×17, 13×9, every one with
/// a cut 2×2 block at the border) cut into 20-px tiles (tile corners at odd positions of the
/// coarser grids), tiled reconstruction equals the whole image on both engines, and a tile
/// smaller than the U-Net's 43-px reach still sees all it needs.
/// Networks reading extra feature planes (a U-Net and a dual tiny network): the native engine
/// computes what Burn computes, tiles equal the whole image, and the planes change the output
/// (a network fed zero planes reconstructs something else).
#[test]
fn extra_feature_planes_reach_both_engines_and_every_tile() {
    use model::features::{pack_with, ExtraFeature};
    let (mut bundle, _) = synthetic_bundle(45, 29, 0.3, 17);
    bundle.meta.passes = 128;
    let device = Device::flex();
    let extra = vec![ExtraFeature::Disagreement, ExtraFeature::Passes];
    for (name, config) in [
        (
            "unet",
            ModelConfig::preset(Preset::UNet).with_extra_features(extra.clone()),
        ),
        (
            "dual tiny",
            ModelConfig::preset(Preset::Tiny)
                .with_extra_features(extra.clone())
                .with_levels(vec![0, 2]),
        ),
    ] {
        config.validate().unwrap();
        let m = TrainedModel {
            dir: PathBuf::new(),
            network: with_distinct_biases(config.init(19, &device)),
            config,
        };
        let packed = pack_with(&bundle, &m.config.packing()).unwrap();
        let burn = reconstruct_tiled(&m, &packed, 0, Engine::Burn, &device, |_, _| {});
        let native = reconstruct_tiled(&m, &packed, 0, Engine::Native, &device, |_, _| {});
        let d = max_relative_difference(&native.image, &burn.image);
        assert!(d <= 2e-5, "{name}: native differs from Burn by {d:e}");
        for engine in [Engine::Native, Engine::Burn] {
            let tiled = reconstruct_tiled(&m, &packed, 16, engine, &device, |_, _| {});
            let d = max_relative_difference(&tiled.image, &native.image);
            assert!(d <= 2e-5, "{name} {engine:?}: tiles differ by {d:e}");
        }
        let mut blind = packed.clone();
        let base = model::network::INPUT_CHANNELS * packed.pixels();
        blind.features[base..].fill(0.0);
        let without = reconstruct_tiled(&m, &blind, 0, Engine::Native, &device, |_, _| {});
        let d = max_relative_difference(&without.image, &native.image);
        assert!(
            d > 1e-3,
            "{name}: the extra planes change the output by only {d:e}"
        );
    }
}

#[test]
fn unet_tiles_equal_the_whole_image_on_sides_not_multiple_of_8() {
    let (bundle, _) = synthetic_bundle(101, 67, 0.3, 13);
    let packed = pack(&bundle).unwrap();
    let device = Device::flex();
    let m = model(Preset::UNet, Weighting::Relu, 21);
    assert_eq!(m.config.conv_reach(), 43);
    for engine in [Engine::Native, Engine::Burn] {
        let whole = reconstruct_tiled(&m, &packed, 0, engine, &device, |_, _| {});
        for tile in [20, 37] {
            let tiled = reconstruct_tiled(&m, &packed, tile, engine, &device, |_, _| {});
            let d = max_relative_difference(&tiled.image, &whole.image);
            assert!(d <= 1e-5, "{engine:?} tile {tile}: differs by {d:e}");
            let d = max_abs_difference(&tiled.shares, &whole.shares);
            assert!(d <= 1e-5, "{engine:?} tile {tile}: shares differ by {d:e}");
        }
    }
}

#[test]
fn saved_model_directory_reloads_to_identical_output() {
    for preset in [Preset::Tiny, Preset::UNet] {
        let dir = temp_dir(&format!("roundtrip-{preset:?}"));
        let m = model(preset, Weighting::Relu, 5);
        save_burnpack(&m.network, &dir.join("model.bpk")).unwrap();
        std::fs::write(
            dir.join("model.json"),
            serde_json::to_string(&m.config).unwrap(),
        )
        .unwrap();
        let device = Device::flex();
        let loaded = TrainedModel::open(&dir, &device).unwrap();
        assert_eq!(loaded.config, m.config);
        assert_eq!(loaded.network.unet, m.config.unet);
        let (bundle, _) = synthetic_bundle(19, 13, 0.2, 3);
        let packed = pack(&bundle).unwrap();
        for engine in [Engine::Burn, Engine::Native] {
            let a = reconstruct_tiled(&m, &packed, 0, engine, &device, |_, _| {});
            let b = reconstruct_tiled(&loaded, &packed, 0, engine, &device, |_, _| {});
            assert!(a == b, "{preset:?} {engine:?}: reloaded output differs");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn missing_or_broken_model_files_are_named() {
    let dir = temp_dir("broken");
    let device = Device::flex();
    let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
    assert!(err.contains("model.json"), "{err}");
    std::fs::write(dir.join("model.json"), "{\"preset\": \"tiny\"").unwrap();
    let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
    assert!(err.contains("model.json"), "{err}");
    let config = ModelConfig::preset(Preset::Tiny);
    std::fs::write(
        dir.join("model.json"),
        serde_json::to_string(&config).unwrap(),
    )
    .unwrap();
    let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
    assert!(err.contains("model.bpk"), "{err}");
    // Weights of another architecture do not load silently: the error names the weights file
    // and the tensor whose shape differs.
    let other = ModelConfig::preset(Preset::Small).init(1, &device);
    save_burnpack(&other, &dir.join("model.bpk")).unwrap();
    let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
    assert!(
        err.contains("model.bpk") && err.contains("ShapeMismatch") && err.contains("hidden.0"),
        "{err}"
    );
    // Nor do those of a deeper network whose first layers have this network's shapes.
    let deeper = ModelConfig {
        hidden_layers: config.hidden_layers + 1,
        ..config.clone()
    };
    save_burnpack(&deeper.init(1, &device), &dir.join("model.bpk")).unwrap();
    let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
    assert!(
        err.contains("model.bpk") && err.contains(&format!("hidden.{}", config.hidden_layers)),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Writes a model directory (`model.json` + `model.bpk`) of a random tiny network into `dir`.
fn write_tiny_model(dir: &Path) {
    let m = model(Preset::Tiny, Weighting::Relu, 5);
    save_burnpack(&m.network, &dir.join("model.bpk")).unwrap();
    std::fs::write(
        dir.join("model.json"),
        serde_json::to_string(&m.config).unwrap(),
    )
    .unwrap();
}

/// `infer --model dir --input input --output output`, to be given more arguments.
fn infer_input(
    dir: &Path,
    input: impl AsRef<std::ffi::OsStr>,
    output: impl AsRef<std::ffi::OsStr>,
) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_infer"));
    cmd.arg("--model")
        .arg(dir)
        .arg("--input")
        .arg(input)
        .arg("--output")
        .arg(output);
    cmd
}

#[test]
fn cli_names_a_missing_bundle_and_exits_non_zero() {
    let dir = temp_dir("cli");
    write_tiny_model(&dir);
    let out = infer_input(&dir, dir.join("nope.exr"), dir.join("out.exr"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("nope.exr"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!dir.join("out.exr").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Finite input values so large that the combination overflows float32 give an error naming
/// the bundle and a pixel, and no output image (not an image of infinities, nor one the guard
/// or the clamp turned into zeros, with exit 0) — on both engines, guard on and off.
#[test]
fn cli_refuses_to_write_a_non_finite_reconstruction() {
    let dir = temp_dir("cli-overflow");
    write_tiny_model(&dir);
    let (mut bundle, _) = synthetic_bundle(12, 10, 0.1, 3);
    for level in &mut bundle.levels {
        level.data.fill(3.0e38);
    }
    let input = dir.join("huge.exr");
    bundle::write_bundle(&input, &bundle).unwrap();
    for (engine, guard) in [
        ("native", "16"),
        ("burn", "16"),
        ("native", "0"),
        ("burn", "0"),
    ] {
        let out = infer_input(&dir, &input, dir.join("out.exr"))
            .args(["--engine", engine, "--guard", guard])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{engine} {guard}: {stderr}");
        assert!(
            stderr.contains("huge.exr") && stderr.contains("not finite at pixel"),
            "{engine} {guard}: {stderr}"
        );
        assert!(!dir.join("out.exr").exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--threads` bounds the reconstruction of a given bundle too, and changes nothing in it.
#[test]
fn cli_threads_apply_to_the_reconstruction_and_change_nothing() {
    let dir = temp_dir("cli-threads");
    write_tiny_model(&dir);
    let (bundle, _) = synthetic_bundle(40, 24, 0.2, 8);
    let input = dir.join("b.exr");
    bundle::write_bundle(&input, &bundle).unwrap();
    let run = |threads: &str| {
        let output = dir.join(format!("out{threads}.exr"));
        let out = infer_input(&dir, &input, &output)
            .args(["--threads", threads])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        bundle::read_rgb_exr_image(&output).unwrap().data
    };
    let one = run("1");
    assert!(one == run("2"), "the output depends on --threads");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cli_refuses_rendering_options_without_a_scene() {
    let dir = temp_dir("cli-input-only");
    write_tiny_model(&dir);
    for (option, flag) in [
        (&["--passes", "256"][..], "--passes"),
        (&["--time", "60"][..], "--time"),
        (&["--photons", "1000"][..], "--photons"),
        (&["--schedule", "cppm"][..], "--schedule"),
        (&["--seed", "3"][..], "--seed"),
        (&["--max-depth", "4"][..], "--max-depth"),
        (&["--lenient"][..], "--lenient"),
        (&["-D", "res=64"][..], "-D"),
        (&["--state", "s.state"][..], "--state"),
    ] {
        let out = infer_input(&dir, dir.join("bundle.exr"), dir.join("out.exr"))
            .args(option)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{option:?}: {stderr}");
        assert!(
            stderr.contains(&format!("{flag} sets how --scene renders")),
            "{stderr}"
        );
        // Refused before the bundle is looked at: the usage error, not a missing file (the
        // usage line names `<bundle.exr>`, not this bundle's path).
        let bundle = dir.join("bundle.exr");
        assert!(!stderr.contains(bundle.to_str().unwrap()), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cli_renders_a_scene_by_passes_or_by_time_then_reconstructs() {
    let dir = temp_dir("cli-scene");
    write_tiny_model(&dir);
    // The repository's diffuse Cornell box at 16×16.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/validation/cornell-diffuse/scene.xml");
    let infer = |name: &str, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_infer"))
            .arg("--model")
            .arg(&dir)
            .arg("--scene")
            .arg(&scene)
            .args([
                "-D",
                "res=16",
                "--photons",
                "2000",
                "--threads",
                "2",
                "--output",
            ])
            .arg(dir.join(format!("{name}.exr")))
            .args(extra)
            .output()
            .unwrap()
    };
    let passes_of = |name: &str| {
        bundle::read_bundle(&dir.join(format!("{name}_bundle.exr")))
            .unwrap()
            .meta
            .passes
    };
    // By passes: exactly that many.
    let out = infer("passes", &["--passes", "3"]);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(passes_of("passes"), 3);
    assert!(dir.join("passes.exr").is_file());
    // By time: the render goes on past the limit's first pass end, with no pass limit.
    let out = infer("timed", &["--time", "0.05"]);
    assert!(out.status.success(), "{out:?}");
    let bundle = bundle::read_bundle(&dir.join("timed_bundle.exr")).unwrap();
    assert!(bundle.meta.passes >= 1);
    assert!(bundle.meta.seconds >= 0.05, "{}", bundle.meta.seconds);
    assert!(dir.join("timed.exr").is_file());
    // Both: the pass count comes first here.
    let out = infer("both", &["--passes", "2", "--time", "600"]);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(passes_of("both"), 2);
    // `--schedule cppm` renders multi-level CPPM, recorded in the bundle.
    let out = infer("cppm", &["--passes", "2", "--schedule", "cppm"]);
    assert!(out.status.success(), "{out:?}");
    let cppm = bundle::read_bundle(&dir.join("cppm_bundle.exr")).unwrap();
    assert_eq!(
        (cppm.meta.integrator.as_str(), cppm.meta.schedule.as_str()),
        ("sppm-ml", "cppm")
    );
    // Bad limits are named, and nothing is written.
    for (args, needle) in [
        (
            &["--time", "0"][..],
            "--time must be a positive, finite number of seconds, got 0",
        ),
        (&["--time", "inf"][..], "got inf"),
        (&["--time", "nan"][..], "got NaN"),
        (&["--passes", "0"][..], "--passes must be at least 1"),
    ] {
        let out = infer("bad", args);
        assert!(!out.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!dir.join("bad.exr").exists());
    }
    // The scene policy of every command (renderer::scene_file): a define the scene never reads
    // (a misspelt name) is an error naming it, before anything is rendered.
    let out = infer("misspelt", &["--passes", "1", "-D", "rez=16"]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("-D rez=16") && stderr.contains("scene.xml"),
        "{stderr}"
    );
    assert!(!dir.join("misspelt.exr").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--whole-levels --guard 0` is the paper's reconstruction (Eq. 6 on the whole levels): a
/// light that path A saw in one pixel spreads over the window (the halo the emission split
/// removes), while the default keeps it in its pixel; `--guard` must be a number ≥ 0.
#[test]
fn cli_whole_levels_and_guard_give_the_papers_eq6() {
    let dir = temp_dir("cli-whole");
    write_tiny_model(&dir);
    let (w, h) = (16, 12);
    let (mut bundle, _) = synthetic_bundle(w, h, 0.3, 8);
    bundle.direct = Some(no_direct_light(w, h));
    let light = 5000.0f32;
    add_light_seen_by_path_a(&mut bundle, 8, 6, light);
    let input = dir.join("lit.exr");
    bundle::write_bundle(&input, &bundle).unwrap();
    let run = |name: &str, extra: &[&str]| {
        let out = infer_input(&dir, &input, dir.join(format!("{name}.exr")))
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        bundle::read_rgb_exr_image(&dir.join(format!("{name}.exr"))).unwrap()
    };
    let split = run("split", &[]);
    let paper = run("paper", &["--whole-levels", "--guard", "0"]);
    // The brightest pixel other than the light's, in each image.
    let brightest_neighbour = |img: &bundle::Image| {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| (x, y) != (8, 6))
            .map(|(x, y)| img.get(x, y, 0))
            .fold(0.0f32, f32::max)
    };
    assert!(
        brightest_neighbour(&paper) > 0.01 * light,
        "Eq. 6 on the whole levels should spread the light: {}",
        brightest_neighbour(&paper)
    );
    assert!(
        brightest_neighbour(&split) < 0.002 * light,
        "the split keeps the light in its pixel: {}",
        brightest_neighbour(&split)
    );
    assert!(split.get(8, 6, 0) > 0.4 * light);
    let bad = infer_input(&dir, &input, dir.join("bad.exr"))
        .args(["--guard", "nan"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(1), "{bad:?}");
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--guard"));
    assert!(!dir.join("bad.exr").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
