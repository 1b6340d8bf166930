//! The stress set (scenes/stress, docs/results.md "Never worse than its inputs"): scenes built to
//! break a window filter — a light smaller than a pixel seen directly, a light seen through glass
//! and in a mirror, caustic fireflies in the sharp level, a saturated highlight next to black —
//! rendered here with multi-level SPPM and reconstructed with the shipped weights and defaults
//! (models/default, models/unet-es2, models/small and models/paper: emission split and guard).
//! On each, the output's relMSE against the scene's shipped reference must be at most 1.05 ×
//! that of the best input level: the reconstruction never makes the image worse than what went
//! in. And a light that one subpath saw in one pixel stays in that pixel.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use infer::{reconstruct_tiled, Engine, ErrorReport};
use model::features::{pack, pack_with, planar_reference};
use model::model_dir::TrainedModel;
use renderer::integrators::sppm::{render_sppm, SppmMode, SppmSettings, StopCondition};

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The weights shipped in the repository, each held to the same bound.
const SHIPPED_MODELS: [&str; 4] = [
    "models/default",
    "models/unet-es2",
    "models/small",
    "models/paper",
];

/// Renders stress scene `name` at 64×64 with multi-level SPPM and reconstructs it with each of
/// `models`: the error reports against the scene's reference, in their order.
fn stress_reports(
    name: &str,
    passes: u32,
    photons: u64,
    models: &[TrainedModel],
    device: &Device,
) -> Vec<ErrorReport> {
    let dir = repository().join("scenes/stress").join(name);
    let loaded = renderer::scene_file::load_for_sppm(&dir.join("scene.xml"), &[], false).unwrap();
    let settings = SppmSettings {
        photons_per_pass: photons,
        seed: 1,
        mode: SppmMode::MultiLevel,
        max_depth: 12,
        threads: 2,
        scene_name: name.into(),
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: vec![passes],
        seconds: None,
    };
    let mut bundle = None;
    render_sppm(
        &loaded.scene,
        &settings,
        &stop,
        |b| {
            bundle = Some(b);
            Ok(())
        },
        |_| {},
    )
    .unwrap();
    let bundle = bundle.expect("one bundle");
    let packed = pack(&bundle).unwrap();
    let reference = bundle::read_rgb_exr_image(&dir.join("reference.exr")).unwrap();
    let reference = planar_reference(&reference, packed.width, packed.height).unwrap();
    models
        .iter()
        .map(|model| {
            // The model's input: its screen levels (if any) in place; the report is on the
            // levels as rendered.
            let input = pack_with(&bundle, &model.config.packing()).unwrap();
            let out = reconstruct_tiled(model, &input, 0, Engine::Native, device, |_, _| {});
            ErrorReport::new(&packed, &out.image, &reference)
        })
        .collect()
}

/// Output relMSE ≤ 1.05 × the best input level's on every stress scene, at two photon
/// densities (≈ 5 and ≈ 0.5 photons per pixel per pass: the second one speckles ỹ).
#[test]
fn never_worse_than_the_best_input_level() {
    let device = Device::flex();
    let models: Vec<TrainedModel> = SHIPPED_MODELS
        .iter()
        .map(|m| TrainedModel::open(&repository().join(m), &device).unwrap())
        .collect();
    let mut failures = Vec::new();
    for name in [
        "subpixel-light",
        "glass-mirror",
        "caustic-fireflies",
        "highlight-black",
    ] {
        for (passes, photons) in [(32, 20_000), (32, 2_000)] {
            for (model, r) in SHIPPED_MODELS
                .iter()
                .zip(stress_reports(name, passes, photons, &models, &device))
            {
                eprintln!(
                    "{model}, {name} {passes} x {photons}: output {:.4e}, best input {} {:.4e}, \
                     ratio {:.3}",
                    r.output, r.best_level, r.best_level_relmse, r.ratio_to_best
                );
                if r.ratio_to_best.is_nan() || r.ratio_to_best > 1.05 {
                    failures.push(format!(
                        "{model}, {name} at {passes} x {photons}: {:.3}",
                        r.ratio_to_best
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "worse than the best input: {failures:?}"
    );
}
