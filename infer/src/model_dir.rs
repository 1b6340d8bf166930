//! A trained model directory (`model.json` + `model.bpk`): the loader lives in the `model`
//! crate (`train` reads such directories too); re-exported here for `infer` users.

pub use model::model_dir::{ModelDirError, TrainedModel, CONFIG_FILE, WEIGHTS_FILE};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{reconstruct_tiled, Engine};
    use burn::tensor::Device;
    use model::synthetic::synthetic_sample;
    use model::training::save_burnpack;
    use model::ModelConfig;
    use model::Preset;

    #[test]
    fn dual_model_directory_reconstructs_from_its_levels() {
        let dir = std::env::temp_dir().join(format!("model-dir-dual-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let device = Device::flex();
        let config = ModelConfig::preset(Preset::Tiny).with_levels(vec![0, 3]);
        save_burnpack(&config.init(4, &device), &dir.join(WEIGHTS_FILE)).unwrap();
        std::fs::write(
            dir.join(CONFIG_FILE),
            serde_json::to_string(&config).unwrap(),
        )
        .unwrap();
        let model = TrainedModel::open(&dir, &device).unwrap();
        assert_eq!(model.config.levels, vec![0, 3]);

        // ỹ copied into z̃3: the dual combination must return ỹ (consistency), tiled or not,
        // whatever z̃1, z̃2, z̃4 hold; all weight sits on z̃3.
        let mut packed = synthetic_sample(13, 11, 0.2, 8).packed;
        let pixels = packed.pixels();
        let y = packed.level(0).to_vec();
        packed.levels[9 * pixels..12 * pixels].copy_from_slice(&y);
        for (tile, engine) in [
            (0, Engine::Burn),
            (4, Engine::Burn),
            (0, Engine::Native),
            (4, Engine::Native),
        ] {
            let rec = reconstruct_tiled(&model, &packed, tile, engine, &device, |_, _| {});
            for (o, e) in rec.image.iter().zip(&y) {
                assert!(
                    (o - e).abs() <= 1e-4 * e.abs().max(1.0),
                    "tile {tile} {engine:?}: {o} vs {e}"
                );
            }
            assert_eq!(rec.shares.len(), 4 * pixels);
            for (j, plane) in rec.shares.chunks(pixels).enumerate() {
                let want = if j == 2 { 1.0 } else { 0.0 };
                assert!(
                    plane.iter().all(|s| (s - want).abs() < 1e-5),
                    "share plane {j}"
                );
            }
        }

        // A model.json whose levels disagree with in_channels is refused, naming the file.
        let mut bad = config.clone();
        bad.in_channels = 27;
        std::fs::write(dir.join(CONFIG_FILE), serde_json::to_string(&bad).unwrap()).unwrap();
        let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
        assert!(
            err.contains("model.json") && err.contains("in_channels"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
