//! The frozen held-out set (`scenes/heldout`, written by `scripts/freeze_heldout.py`): every
//! listed scene loads for SPPM at its recorded size, its reference is the file its checksum
//! names, of that size and finite, and every evaluate config that reads the set names frozen
//! scenes with their recorded noise.

use serde::Deserialize;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
struct Frozen {
    scenes: Vec<FrozenScene>,
}

#[derive(Deserialize)]
struct FrozenScene {
    id: String,
    size: [u32; 2],
    reference_sha256: String,
    reference_noise: f64,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn sha256(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn frozen() -> Frozen {
    let path = root().join("scenes/heldout/scenes.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn frozen_scenes_load_and_their_references_match_their_records() {
    let frozen = frozen();
    assert!(!frozen.scenes.is_empty());
    for s in &frozen.scenes {
        let dir = root().join("scenes/heldout").join(&s.id);
        let reference = dir.join("reference.exr");
        assert_eq!(sha256(&reference), s.reference_sha256, "{}", s.id);
        let image = bundle::read_rgb_exr_image(&reference).unwrap();
        assert_eq!(
            [image.width as u32, image.height as u32],
            s.size,
            "{}",
            s.id
        );
        assert!(
            image.data.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{}",
            s.id
        );
        let loaded = renderer::scene_file::load_for_sppm(&dir.join("scene.xml"), &[], false)
            .unwrap_or_else(|e| panic!("{}: {e:#}", s.id));
        let r = loaded.scene.camera.resolution();
        assert_eq!([r.x, r.y], s.size, "{}", s.id);
        assert!(s.reference_noise.is_finite() && s.reference_noise > 0.0);
    }
}

#[test]
fn configs_reading_the_set_name_frozen_scenes_with_their_noise() {
    let frozen = frozen();
    let mut configs = 0;
    for entry in std::fs::read_dir(root().join("configs/eval")).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        if !text.contains("scenes/heldout/") {
            continue;
        }
        configs += 1;
        let config = evaluate::config::EvalConfig::load(&path).unwrap();
        assert!(!config.scenes.is_empty(), "{}", path.display());
        for scene in &config.scenes {
            let id = scene
                .xml
                .parent()
                .and_then(|p| p.file_name())
                .and_then(|n| n.to_str())
                .unwrap();
            let f = frozen
                .scenes
                .iter()
                .find(|f| f.id == id)
                .unwrap_or_else(|| panic!("{}: {id} is not frozen", path.display()));
            assert_eq!(
                scene.reference,
                Path::new("scenes/heldout").join(id).join("reference.exr")
            );
            let noise = scene.reference_noise.unwrap();
            assert!(
                (noise / f.reference_noise - 1.0).abs() < 1e-5,
                "{}: {id}",
                path.display()
            );
        }
    }
    assert!(configs >= 2, "the held-out configs read scenes/heldout");
}
