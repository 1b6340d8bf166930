//! Robustness of the whole load → build → render chain against bad values: every validation
//! scene of the repository and the bundled default scene, with one attribute value at a time
//! replaced by something hostile (zero, negative, huge, tiny, NaN, infinity, empty, text, a
//! wrong arity), must either load and render (path tracer and one multi-level SPPM pass,
//! without a panic and without non-finite pixels) or fail with an error that names the scene
//! file — never panic.

use renderer::integrators::path::PathTracer;
use renderer::integrators::sppm::{render_sppm, SppmSettings, StopCondition};
use renderer::integrators::RayIntegrator;
use renderer::scene::Scene;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

/// Values put in place of a parameter's.
const HOSTILE: [&str; 11] = [
    "0", "-1", "1e30", "-1e30", "1e-30", "nan", "inf", "", "abc", "0, 0, 0", "0.5, 0.5",
];

/// Mutants per scene (a fixed, seeded choice of attribute and value).
const MUTANTS_PER_SCENE: usize = 40;

/// The attribute values of an XML text (byte ranges inside the quotes of every `name="…"`:
/// values, transform arguments, plugin types, parameter names, file names).
fn value_spans(text: &str) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut from = 0;
    while let Some(i) = text[from..].find("=\"") {
        let start = from + i + "=\"".len();
        let Some(len) = text[start..].find('"') else {
            break;
        };
        spans.push((start, start + len));
        from = start + len;
    }
    spans
}

/// SplitMix64: a tiny seeded generator for picking mutations (deterministic across runs).
fn next(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Loads, builds and renders `path` tiny; `Err` with the message when the input is refused.
fn load_and_render(path: &Path) -> Result<(), String> {
    // Small films and few samples keep a mutant cheap (scenes without these defaults keep
    // their own, small, film sizes).
    let defaults = [
        ("res".to_owned(), "8".to_owned()),
        ("spp".to_owned(), "1".to_owned()),
    ];
    let desc = renderer::xml::load_scene(path, &defaults, false).map_err(|e| e.to_string())?;
    let scene = Scene::build(&desc).map_err(|e| format!("{}: {e:#}", path.display()))?;
    let film = PathTracer {
        max_depth: 6,
        rr_depth: 5,
    }
    .render(&scene, 1, 7, None);
    let res = scene.camera.resolution();
    for y in 0..res.y {
        for x in 0..res.x {
            let p = film.get(x, y);
            assert!(p.is_finite(), "{}: pixel ({x}, {y}) is {p}", path.display());
        }
    }
    let settings = SppmSettings {
        photons_per_pass: 500,
        seed: 3,
        threads: 1,
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: vec![1],
        seconds: None,
    };
    render_sppm(&scene, &settings, &stop, |_| Ok(()), |_| {})
        .map(|_| ())
        .map_err(|e| format!("{}: {e:#}", path.display()))
}

#[test]
fn mutated_validation_scenes_never_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/validation");
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path().join("scene.xml"))
        .filter(|p| p.exists())
        .collect();
    scenes.sort();
    scenes.push(root.join("../default/scene.xml"));
    assert!(scenes.len() >= 20, "{}", scenes.len());
    let (mut refused, mut rendered) = (0, 0);
    let mut state = 20_261_124_u64;
    for scene in &scenes {
        let text = std::fs::read_to_string(scene).unwrap();
        let spans = value_spans(&text);
        assert!(!spans.is_empty(), "{}", scene.display());
        for m in 0..MUTANTS_PER_SCENE {
            let (start, end) = spans[next(&mut state) as usize % spans.len()];
            let value = HOSTILE[next(&mut state) as usize % HOSTILE.len()];
            let mutant = format!("{}{value}{}", &text[..start], &text[end..]);
            // Next to the original, so that its relative mesh and texture paths still resolve.
            let path = scene.with_file_name(format!(".mutant-{}-{m}.xml", std::process::id()));
            std::fs::write(&path, &mutant).unwrap();
            let outcome = catch_unwind(AssertUnwindSafe(|| load_and_render(&path)));
            std::fs::remove_file(&path).unwrap();
            let what = format!(
                "{} with value {:?} at byte {start} (was {:?})",
                scene.display(),
                value,
                &text[start..end]
            );
            match outcome {
                Ok(Ok(())) => rendered += 1,
                Ok(Err(message)) => {
                    assert!(
                        message.contains(&format!(".mutant-{}-{m}.xml", std::process::id())),
                        "{what}: the error does not name the file: {message}"
                    );
                    refused += 1;
                }
                Err(_) => panic!("{what}: panicked"),
            }
        }
    }
    eprintln!(
        "{} scenes: {refused} mutants refused, {rendered} rendered",
        scenes.len()
    );
    // Both outcomes occur: the mutations are neither all harmless nor all fatal.
    assert!(
        refused > 10 && rendered > 10,
        "{refused} refused, {rendered} rendered"
    );
}
