//! Dataset generation for multi-level SPPM post-reconstruction: procedural randomized scene
//! families written as Mitsuba 3 XML + PLY, kill-safe sharded rendering of references and input
//! bundles, the dataset manifest, dataset checks and contact sheets. See `docs/datagen.md`.

pub mod average;
pub mod check;
pub mod config;
pub mod contact_sheet;
pub mod evaluation_reference;
pub mod families;
pub mod fsutil;
pub mod jobs;
pub mod manifest;
pub mod mesh;
pub mod plan;
pub mod ply;
pub mod reference_noise;
pub mod rng;
pub mod scene;
pub mod sppm_backend;
pub mod xml;
