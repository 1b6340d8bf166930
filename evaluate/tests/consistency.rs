//! Consistency of the reconstruction with screen-space filters (docs/method.md §9): on a scene
//! with a path-traced reference, the error of Eq. 6 over levels that include screen-filtered
//! ones, plus the direct-filtered photon-free part, falls towards zero from 64 to 4 096 passes,
//! whatever the network's weights (here random ones): every level converges, the filters'
//! bandwidth shrinks with the passes, and Eq. 6 converges when its levels do.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use evaluate::peers::path_trace_progressive;
use infer::{reconstruct_tiled, Engine};
use model::features::pack_with;
use model::metrics::relmse_planar;
use model::model_dir::TrainedModel;
use model::screen_filter::{DirectFilter, ScreenLevel};
use model::{ModelConfig, Preset};
use renderer::integrators::path::PathTracer;
use renderer::integrators::sppm::{render_sppm_resumable, SppmMode, SppmSettings, StopCondition};

const SIDE: &str = "16";
const PASSES: [u32; 4] = [64, 256, 1024, 4096];

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/validation/cornell-diffuse/scene.xml")
}

#[test]
fn screen_levels_converge_with_passes() {
    let defines = vec![("res".to_owned(), SIDE.to_owned())];
    let scene = renderer::scene_file::load_for_sppm(&scene_path(), &defines, false)
        .unwrap()
        .scene;
    let res = scene.camera.resolution();
    let pixels = (res.x * res.y) as usize;
    // The reference: unbounded path tracing (Russian roulette), 16 384 samples per pixel —
    // deeper than SPPM's 16-bounce photon paths, so both see the same light.
    let tracer = PathTracer {
        max_depth: -1,
        rr_depth: 5,
    };
    let mut reference = vec![0.0f32; 3 * pixels];
    path_trace_progressive(&scene, &tracer, 11, f64::INFINITY, 16384, |_, _, image| {
        reference.copy_from_slice(image);
    });
    let settings = SppmSettings {
        photons_per_pass: 4000,
        seed: 5,
        mode: SppmMode::MultiLevel,
        max_depth: 16,
        threads: 0,
        scene_name: "cornell-diffuse".into(),
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: PASSES.to_vec(),
        seconds: None,
    };
    let mut bundles = Vec::new();
    render_sppm_resumable(
        &scene,
        &settings,
        &stop,
        None,
        |b| {
            bundles.push(b);
            Ok(())
        },
        |_| {},
    )
    .unwrap();
    assert_eq!(bundles.len(), PASSES.len());

    let mut config = ModelConfig::preset(Preset::Tiny);
    config.screen_levels = vec![
        ScreenLevel {
            slot: 4,
            source: 4,
            sigma: 2.0,
            range: 2.0,
        },
        ScreenLevel {
            slot: 3,
            source: 2,
            sigma: 3.0,
            range: 0.0,
        },
    ];
    // Twice the shipped σ₀, so that the filter still averages at 4 096 passes (σ = 1 px).
    config.direct_filter = Some(DirectFilter {
        sigma: 2.0,
        range: 4.0,
    });
    config.validate().unwrap();
    let model = TrainedModel {
        dir: PathBuf::new(),
        network: config.init(7, &Device::flex()),
        config,
    };
    let mut errors = Vec::new();
    for b in &bundles {
        let packed = pack_with(b, &model.config.packing()).unwrap();
        let out = reconstruct_tiled(
            &model,
            &packed,
            64,
            Engine::Native,
            &Device::flex(),
            |_, _| {},
        );
        errors.push(relmse_planar(&out.image, &reference));
    }
    eprintln!("relMSE at {PASSES:?} passes: {errors:?}");
    for w in errors.windows(2) {
        assert!(w[1] < w[0], "the error grew with the passes: {errors:?}");
    }
    assert!(
        errors[3] < 0.2 * errors[0],
        "the error did not fall towards zero: {errors:?}"
    );
}
