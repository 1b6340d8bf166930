//! Shared helpers of the datagen integration tests: tiny configs, directory snapshots.

#![allow(dead_code)]

use bundle::{Bundle, BundleMeta, Image};
use datagen::config::Config;
use datagen::jobs::RunSpec;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The tiny preset shrunk further for tests: 16×16, the given passes and seeds.
pub fn test_config(width: u32, passes: &[u32], seeds: u32, reference_passes: u32) -> Config {
    let root = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_else(|| env!("CARGO_MANIFEST_DIR").into()),
    )
    .join("../configs/datagen/tiny.toml");
    let mut c = Config::load(&root).expect("tiny config parses");
    c.width = width;
    c.height = width;
    c.render.passes = Some(passes.to_vec());
    c.render.seeds = seeds;
    c.render.reference_passes = reference_passes;
    c
}

/// A fresh empty directory under the system temp dir.
pub fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("datagen-it-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every regular file under `root` (relative path → bytes), except wall-clock `timings/`.
pub fn snapshot(root: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(root, root, &mut out);
    out.retain(|k, _| !k.starts_with("timings/"));
    out
}

/// Asserts two snapshots hold the same files with the same bytes, naming the first difference.
pub fn assert_same(a: &BTreeMap<String, Vec<u8>>, b: &BTreeMap<String, Vec<u8>>) {
    let ka: Vec<_> = a.keys().collect();
    let kb: Vec<_> = b.keys().collect();
    assert_eq!(ka, kb, "different file sets");
    for (k, v) in a {
        assert!(v == &b[k], "{k} differs");
    }
}

/// A stand-in renderer's bundle of `spec` at `passes`: every layer is `image(channels, salt)`
/// (salts: levels 1–5, variance 10, albedo 11, normal 12, depth 13, radius 14, ydirect 15,
/// zdirect 16, directvariance 17; the photon-free layers come with the radius, as a render
/// writes both).
pub fn stand_in_bundle(
    spec: &RunSpec,
    passes: u32,
    (width, height): (usize, usize),
    with_radius: bool,
    image: impl Fn(usize, usize) -> Image,
) -> Bundle {
    Bundle {
        meta: BundleMeta {
            scene: spec.sppm.scene_name.clone(),
            seed: spec.sppm.seed,
            passes,
            photons_per_pass: spec.sppm.photons_per_pass,
            seconds: 1.5,
            integrator: "sppm-ml".into(),
            schedule: bundle::DEFAULT_SCHEDULE.into(),
            emitter_samples: 1,
            sharp_level: "a".into(),
            sampler: "independent".into(),
            width: width as u32,
            height: height as u32,
        },
        levels: (0..5).map(|l| image(3, l + 1)).collect(),
        variance: image(5, 10),
        albedo: image(3, 11),
        normal: image(3, 12),
        depth: image(1, 13),
        radius: with_radius.then(|| image(5, 14)),
        direct: with_radius.then(|| bundle::DirectLight {
            y: image(3, 15),
            z: image(3, 16),
            variance: image(2, 17),
        }),
    }
}
