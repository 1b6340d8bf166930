//! The patch dataset: the dataset's manifest (`bundle::manifest`) read, bad-data screening, a bounded image cache, seeded
//! shuffling and flips, and batch assembly.
//!
//! Memory stays bounded for any dataset size: images are loaded lazily and at most
//! `cache_images` packed images are held at once. An epoch visits the images in a shuffled
//! order, in groups of `cache_images`; the patches of one group are shuffled together, so each
//! image is loaded once per epoch while batches still mix several images.
//!
//! A dataset may feed a network that combines only some levels (paper Table 1's Dual variant):
//! batches then carry only those levels' features and colours as network and combination
//! input, and always all five colour planes so validation reports every input level.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bundle::manifest::Manifest;
use burn::tensor::{Device, Tensor, TensorData};
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg64Mcg;

use model::features::{
    colour_channels, feature_channels, split_direct, Packing, COLOUR_CHANNELS, DIRECT_CHANNELS,
};
use model::network::all_levels;
use model::sample::{load_sample, BadSample, Sample};

/// Where a sample's pixels come from: files, or memory (tests, synthetic data).
#[derive(Clone, Debug)]
pub enum SampleSource {
    /// Bundle and reference EXR files.
    Files {
        /// Bundle path.
        bundle: PathBuf,
        /// Reference path.
        reference: PathBuf,
    },
    /// An already loaded sample.
    Memory(Arc<Sample>),
}

/// One usable image of a split.
#[derive(Clone, Debug)]
pub struct ImageEntry {
    /// Where to load it from.
    pub source: SampleSource,
    /// Scene identifier.
    pub scene: String,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The reference's own noise (relMSE against its expectation) where the dataset recorded
    /// it: a converged evaluation reference's, or a training reference averaged from runs.
    pub reference_noise: Option<f64>,
}

/// One training patch: image, top-left corner, flips.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PatchRef {
    /// Index into the dataset's images.
    pub image: usize,
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Mirror left-right.
    pub flip_x: bool,
    /// Mirror top-bottom.
    pub flip_y: bool,
}

/// A batch on the host, planar per patch.
#[derive(Clone, Debug)]
pub struct HostBatch {
    /// Patches in the batch.
    pub len: usize,
    /// Patch side.
    pub size: usize,
    /// Network input channels per patch (27 with every level).
    pub feature_channels: usize,
    /// `[B, feature_channels, P, P]`: the features of the chosen levels and the G-buffer.
    pub features: Vec<f32>,
    /// `[B, 15, P, P]`: raw colours of all five levels (for per-level metrics).
    pub levels: Vec<f32>,
    /// Colour planes per patch the combination reads (3·m).
    pub combined_channels: usize,
    /// `[B, 3·m, P, P]`: raw colours of the chosen levels, ỹ first, less their photon-free
    /// part (the combination's input).
    pub combined: Vec<f32>,
    /// `[B, 3, P, P]`: the photon-free part added to the combined image (zero for a bundle
    /// without photon-free layers; [`model::features::split_direct`]).
    pub direct: Vec<f32>,
    /// `[B, 3, P, P]`.
    pub reference: Vec<f32>,
}

/// A batch as tensors on a device.
#[derive(Clone, Debug)]
pub struct Batch {
    /// Network input `[B, feature_channels, P, P]`.
    pub features: Tensor<4>,
    /// Raw colours of the combined levels less their photon-free part `[B, 3·m, P, P]`.
    pub levels: Tensor<4>,
    /// Photon-free part added after the combination `[B, 3, P, P]`.
    pub direct: Tensor<4>,
    /// Reference `[B, 3, P, P]`.
    pub reference: Tensor<4>,
}

impl HostBatch {
    /// Uploads the batch to `device`.
    pub fn to_device(&self, device: &Device) -> Batch {
        let (b, p) = (self.len, self.size);
        let t = |data: &Vec<f32>, channels: usize| {
            Tensor::<4>::from_data(TensorData::new(data.clone(), [b, channels, p, p]), device)
        };
        Batch {
            features: t(&self.features, self.feature_channels),
            levels: t(&self.combined, self.combined_channels),
            direct: t(&self.direct, 3),
            reference: t(&self.reference, 3),
        }
    }
}

/// Top-left positions of `patch`-wide windows along a side of `size` pixels with `stride`,
/// plus one flush with the far edge so every pixel is covered.
pub fn patch_positions(size: usize, patch: usize, stride: usize) -> Vec<usize> {
    if size < patch {
        return Vec::new();
    }
    let mut positions: Vec<usize> = (0..=size - patch).step_by(stride.max(1)).collect();
    if *positions.last().unwrap() != size - patch {
        positions.push(size - patch);
    }
    positions
}

/// Which scene families of a dataset a run reads (by the manifest's `family`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FamilyFilter {
    /// Only these (absent: all).
    pub only: Option<Vec<String>>,
    /// Not these.
    pub exclude: Vec<String>,
}

impl FamilyFilter {
    /// Whether samples of `family` are read.
    pub fn accepts(&self, family: &str) -> bool {
        self.only
            .as_ref()
            .is_none_or(|only| only.iter().any(|f| f == family))
            && !self.exclude.iter().any(|f| f == family)
    }

    /// The names the filter gives that are no family of the dataset (a misspelt name would
    /// otherwise silently read everything or nothing).
    fn unknown<'a>(&'a self, families: &[&str]) -> Vec<&'a str> {
        self.only
            .iter()
            .flatten()
            .chain(&self.exclude)
            .map(String::as_str)
            .filter(|f| !families.contains(f))
            .collect()
    }
}

/// A split of a dataset, cut into patches, with a bounded cache of loaded images.
pub struct PatchDataset {
    /// Usable images.
    pub images: Vec<ImageEntry>,
    /// Samples screened out when the dataset was opened.
    pub bad: Vec<BadSample>,
    /// Patch side.
    pub patch: usize,
    /// Patch stride.
    pub stride: usize,
    /// Levels batches feed to the network and the combination (indices into ỹ, z̃1..z̃4; all
    /// five unless set with [`PatchDataset::with_levels`]).
    pub levels: Vec<usize>,
    /// How images are packed as they load from files (a model's
    /// [`model::ModelConfig::packing`]: screen-space levels in the place of some bundle levels,
    /// extra feature planes).
    packing: Packing,
    cache_images: usize,
    cache: Vec<(usize, Arc<Sample>)>,
}

impl PatchDataset {
    /// Opens the `split` of the dataset in `root`, loading each image once to screen out bad
    /// data (NaN/Inf, missing reference, mismatched sizes or channels, smaller than a patch).
    /// `references`: a directory inside `root` whose `<scene id>.exr` replaces the manifest's
    /// reference of every sample (e.g. the averaged runs of `datagen average-references`).
    /// Only samples of the families `families` accepts are read. `measure`: the split is
    /// measured, not trained on (validation, `--evaluate`): without `references`, each scene's
    /// converged evaluation reference is used where the manifest lists one (all of the split's
    /// scenes or none: a partial set is refused).
    #[allow(clippy::too_many_arguments)]
    pub fn open(
        root: &Path,
        split: &str,
        patch: usize,
        stride: usize,
        cache_images: usize,
        references: Option<&Path>,
        families: &FamilyFilter,
        measure: bool,
    ) -> Result<Self, String> {
        let manifest: Manifest = Manifest::load(root).map_err(|e| e.to_string())?;
        if let Some(note) = manifest.partial_note(root) {
            eprintln!("note: {note}");
        }
        let mut known: Vec<&str> = manifest.samples.iter().map(|s| s.family.as_str()).collect();
        known.sort_unstable();
        known.dedup();
        let unknown = families.unknown(&known);
        if !unknown.is_empty() {
            return Err(format!(
                "{}: no family {} in the dataset (its families: {})",
                root.join("manifest.json").display(),
                unknown.join(", "),
                known.join(", ")
            ));
        }
        // A misspelt split would otherwise read as an empty one (e.g. training without
        // validation, silently).
        if !manifest.samples.iter().any(|s| s.split.name() == split) {
            let mut splits: Vec<&str> = manifest.samples.iter().map(|s| s.split.name()).collect();
            splits.sort_unstable();
            splits.dedup();
            return Err(format!(
                "{}: no sample in split `{split}` (the manifest's splits: {})",
                root.join("manifest.json").display(),
                splits.join(", ")
            ));
        }
        let read: Vec<_> = manifest
            .samples
            .iter()
            .filter(|s| s.split.name() == split && families.accepts(&s.family))
            .collect();
        if read.is_empty() {
            return Err(format!(
                "{}: split `{split}` has no sample of the families read ({families:?})",
                root.join("manifest.json").display()
            ));
        }
        // The converged evaluation reference of each scene read, where measuring.
        let mut evaluation = std::collections::HashMap::new();
        if measure && references.is_none() {
            let mut without = Vec::new();
            for scene in manifest
                .scenes
                .iter()
                .filter(|s| s.split.name() == split && read.iter().any(|e| e.scene == s.id))
            {
                match &scene.evaluation_reference {
                    Some(e) => {
                        evaluation.insert(scene.id.as_str(), (root.join(&e.path), e.noise));
                    }
                    None => without.push(scene.id.as_str()),
                }
            }
            if !evaluation.is_empty() && !without.is_empty() {
                return Err(format!(
                    "{}: {} scene(s) of split `{split}` have a converged evaluation reference, {} \
                     do not ({}): finish `datagen evaluation-references`, or measure against the \
                     training references with `references = \"references\"`",
                    root.join("manifest.json").display(),
                    evaluation.len(),
                    without.len(),
                    without.join(", ")
                ));
            }
        }
        // The training references' measured noise per scene (datasets with several runs).
        let training_noise: std::collections::HashMap<&str, f64> = manifest
            .scenes
            .iter()
            .filter_map(|s| Some((s.id.as_str(), s.reference_noise?)))
            .collect();
        let mut images = Vec::new();
        let mut bad = Vec::new();
        for entry in read {
            let bundle = root.join(&entry.bundle);
            let (reference, reference_noise) =
                match (references, evaluation.get(entry.scene.as_str())) {
                    (Some(dir), _) => (
                        bundle::scene_reference_path(&root.join(dir), &entry.scene),
                        None,
                    ),
                    (None, Some((path, noise))) => (path.clone(), Some(*noise)),
                    (None, None) => (
                        root.join(&entry.reference),
                        training_noise.get(entry.scene.as_str()).copied(),
                    ),
                };
            // Screening reads the bundle as rendered (the screen levels only replace planes of
            // a bundle that passed these checks).
            match load_sample(&bundle, &reference, &Packing::none()) {
                Ok(sample) => {
                    let (width, height) = (sample.packed.width, sample.packed.height);
                    if width < patch || height < patch {
                        bad.push(BadSample {
                            file: bundle,
                            reason: format!(
                                "image {width}x{height} is smaller than the {patch}x{patch} patch"
                            ),
                        });
                        continue;
                    }
                    images.push(ImageEntry {
                        source: SampleSource::Files { bundle, reference },
                        scene: entry.scene.clone(),
                        width,
                        height,
                        reference_noise,
                    });
                }
                Err(b) => bad.push(b),
            }
        }
        Ok(Self::from_parts(images, bad, patch, stride, cache_images))
    }

    /// A dataset over in-memory samples (synthetic data, tests).
    pub fn from_samples(samples: Vec<Sample>, patch: usize, stride: usize) -> Self {
        let images = samples
            .into_iter()
            .enumerate()
            .map(|(i, s)| ImageEntry {
                width: s.packed.width,
                height: s.packed.height,
                scene: format!("memory-{i}"),
                reference_noise: None,
                source: SampleSource::Memory(Arc::new(s)),
            })
            .collect();
        Self::from_parts(images, Vec::new(), patch, stride, usize::MAX)
    }

    fn from_parts(
        images: Vec<ImageEntry>,
        bad: Vec<BadSample>,
        patch: usize,
        stride: usize,
        cache_images: usize,
    ) -> Self {
        Self {
            images,
            bad,
            patch,
            stride,
            levels: all_levels(),
            packing: Packing::none(),
            cache_images: cache_images.max(1),
            cache: Vec::new(),
        }
    }

    /// Loads images from now on packed as `packing` says (a model's
    /// [`model::ModelConfig::packing`]); cached images of other settings are dropped.
    /// In-memory samples are already packed and stay as they are (their extra planes must be
    /// the packing's).
    pub fn set_packing(&mut self, packing: &Packing) {
        if self.packing != *packing {
            self.packing = packing.clone();
            self.cache.clear();
        }
    }

    /// The same dataset feeding only `levels` (a model's [`model::ModelConfig::levels`]).
    pub fn with_levels(mut self, levels: Vec<usize>) -> Self {
        self.levels = levels;
        self
    }

    /// Patches of image `index` without flips, in raster order.
    pub fn image_patches(&self, index: usize, stride: usize) -> Vec<PatchRef> {
        let entry = &self.images[index];
        let mut out = Vec::new();
        for y in patch_positions(entry.height, self.patch, stride) {
            for x in patch_positions(entry.width, self.patch, stride) {
                out.push(PatchRef {
                    image: index,
                    x,
                    y,
                    flip_x: false,
                    flip_y: false,
                });
            }
        }
        out
    }

    /// Number of training patches per epoch.
    pub fn patches_per_epoch(&self) -> usize {
        (0..self.images.len())
            .map(|i| self.image_patches(i, self.stride).len())
            .sum()
    }

    /// The patch order of `epoch`: a function of (seed, epoch) only, so a resumed run visits
    /// exactly the patches an uninterrupted one would.
    pub fn epoch_plan(&self, seed: u64, epoch: usize) -> Vec<PatchRef> {
        let mut rng =
            Pcg64Mcg::seed_from_u64(seed ^ (epoch as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let mut order: Vec<usize> = (0..self.images.len()).collect();
        shuffle(&mut order, &mut rng);
        let mut plan = Vec::new();
        for group in order.chunks(self.cache_images.min(self.images.len().max(1))) {
            let mut patches: Vec<PatchRef> = group
                .iter()
                .flat_map(|&i| self.image_patches(i, self.stride))
                .collect();
            shuffle(&mut patches, &mut rng);
            for p in &mut patches {
                let bits = rng.next_u32();
                p.flip_x = bits & 1 == 1;
                p.flip_y = bits & 2 == 2;
            }
            plan.extend(patches);
        }
        plan
    }

    /// The loaded image `index`, from the cache or freshly loaded (evicting the least recently
    /// used one when the cache is full).
    pub fn sample(&mut self, index: usize) -> Result<Arc<Sample>, BadSample> {
        if let Some(pos) = self.cache.iter().position(|(i, _)| *i == index) {
            let hit = self.cache.remove(pos);
            let sample = hit.1.clone();
            self.cache.push(hit);
            return Ok(sample);
        }
        let sample = match &self.images[index].source {
            SampleSource::Memory(s) => s.clone(),
            SampleSource::Files { bundle, reference } => {
                Arc::new(load_sample(bundle, reference, &self.packing)?)
            }
        };
        if self.cache.len() >= self.cache_images {
            self.cache.remove(0);
        }
        self.cache.push((index, sample.clone()));
        Ok(sample)
    }

    /// Cuts the patches of `refs` into a host batch.
    pub fn batch(&mut self, refs: &[PatchRef]) -> Result<HostBatch, BadSample> {
        let p = self.patch;
        let features = feature_channels(&self.levels, &self.packing.extra);
        let combined = colour_channels(&self.levels);
        let all_colours: Vec<usize> = (0..COLOUR_CHANNELS).collect();
        let n = refs.len() * p * p;
        let mut batch = HostBatch {
            len: refs.len(),
            size: p,
            feature_channels: features.len(),
            features: Vec::with_capacity(features.len() * n),
            levels: Vec::with_capacity(COLOUR_CHANNELS * n),
            combined_channels: combined.len(),
            combined: Vec::with_capacity(combined.len() * n),
            direct: Vec::with_capacity(3 * n),
            reference: Vec::with_capacity(3 * n),
        };
        let direct_planes: Vec<usize> = (0..DIRECT_CHANNELS).collect();
        let mut patch_direct = Vec::with_capacity(DIRECT_CHANNELS * p * p);
        for r in refs {
            let sample = self.sample(r.image)?;
            let packed = &sample.packed;
            // Images from files are packed with `self.packing`; in-memory ones come packed.
            assert_eq!(
                packed.extra, self.packing.extra,
                "an in-memory sample packed without the model's extra feature planes"
            );
            let (w, h) = (packed.width, packed.height);
            crop(&packed.features, &features, w, h, r, p, &mut batch.features);
            crop(&packed.levels, &all_colours, w, h, r, p, &mut batch.levels);
            let start = batch.combined.len();
            crop(&packed.levels, &combined, w, h, r, p, &mut batch.combined);
            match &packed.direct {
                Some(direct) => {
                    patch_direct.clear();
                    crop(direct, &direct_planes, w, h, r, p, &mut patch_direct);
                    let fused = split_direct(&mut batch.combined[start..], &patch_direct, p * p);
                    match &packed.direct_added {
                        // The model filters the photon-free part: its filtered planes are added.
                        Some(added) => crop(added, &[0, 1, 2], w, h, r, p, &mut batch.direct),
                        None => batch.direct.extend(fused),
                    }
                }
                None => batch.direct.resize(batch.direct.len() + 3 * p * p, 0.0),
            }
            crop(
                &sample.reference,
                &[0, 1, 2],
                w,
                h,
                r,
                p,
                &mut batch.reference,
            );
        }
        Ok(batch)
    }
}

/// Appends the `p`×`p` window of `r` of the planes `channels` (in that order) of planar
/// `h`×`w` data, flipped as `r` says (the same flip for every channel).
fn crop(
    src: &[f32],
    channels: &[usize],
    w: usize,
    h: usize,
    r: &PatchRef,
    p: usize,
    out: &mut Vec<f32>,
) {
    for &c in channels {
        let plane = &src[c * w * h..(c + 1) * w * h];
        for row in 0..p {
            let sy = r.y + if r.flip_y { p - 1 - row } else { row };
            let line = &plane[sy * w + r.x..sy * w + r.x + p];
            if r.flip_x {
                out.extend(line.iter().rev());
            } else {
                out.extend_from_slice(line);
            }
        }
    }
}

/// Fisher–Yates shuffle driven by a PCG stream.
fn shuffle<T>(items: &mut [T], rng: &mut Pcg64Mcg) {
    for i in (1..items.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        items.swap(i, j);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::features::PackedImage;
    use model::network::INPUT_CHANNELS;

    fn ramp_sample(w: usize, h: usize) -> Sample {
        let pixels = w * h;
        let plane = |c: usize| (0..pixels).map(move |i| (c * 1000 + i) as f32);
        Sample {
            packed: PackedImage {
                width: w,
                height: h,
                features: (0..INPUT_CHANNELS).flat_map(plane).collect(),
                extra: Vec::new(),
                levels: (0..COLOUR_CHANNELS).flat_map(plane).collect(),
                direct: None,
                direct_added: None,
            },
            reference: (0..3).flat_map(plane).collect(),
        }
    }

    #[test]
    fn positions_cover_the_image() {
        assert_eq!(patch_positions(10, 4, 4), vec![0, 4, 6]);
        assert_eq!(patch_positions(8, 4, 4), vec![0, 4]);
        assert_eq!(patch_positions(3, 4, 4), Vec::<usize>::new());
    }

    #[test]
    fn flips_are_consistent_across_channels() {
        let mut ds = PatchDataset::from_samples(vec![ramp_sample(5, 4)], 2, 1);
        let r = PatchRef {
            image: 0,
            x: 1,
            y: 2,
            flip_x: true,
            flip_y: true,
        };
        let b = ds.batch(&[r]).unwrap();
        // Unflipped window rows are pixels (2,1),(2,2) / (3,1),(3,2) = indices 11,12 / 16,17;
        // flipped both ways: 17,16 / 12,11, in every channel with its channel offset.
        for c in 0..3 {
            let off = (c * 1000) as f32;
            assert_eq!(
                &b.reference[c * 4..c * 4 + 4],
                &[off + 17.0, off + 16.0, off + 12.0, off + 11.0]
            );
        }
        for c in [0, 26] {
            let off = (c * 1000) as f32;
            assert_eq!(b.features[c * 4], off + 17.0);
        }
    }

    #[test]
    fn dual_batches_carry_their_levels_and_all_colours() {
        let ds = PatchDataset::from_samples(vec![ramp_sample(3, 2)], 2, 1);
        let mut ds = ds.with_levels(vec![0, 3]);
        let r = PatchRef {
            image: 0,
            x: 1,
            y: 0,
            flip_x: false,
            flip_y: false,
        };
        let b = ds.batch(&[r]).unwrap();
        // Window pixels (0,1),(0,2),(1,1),(1,2) = indices 1, 2, 4, 5 of each plane.
        let planes = |cs: &[usize]| -> Vec<f32> {
            cs.iter()
                .flat_map(|&c| [1, 2, 4, 5].map(|i| (c * 1000 + i) as f32))
                .collect()
        };
        // Dual(ỹ, z̃3): colours 0..3 and 9..12, variances 15 and 18, G-buffer 20..27.
        let features = [0, 1, 2, 9, 10, 11, 15, 18, 20, 21, 22, 23, 24, 25, 26];
        assert_eq!(b.feature_channels, 15);
        assert_eq!(b.features, planes(&features));
        assert_eq!(b.combined_channels, 6);
        assert_eq!(b.combined, planes(&[0, 1, 2, 9, 10, 11]));
        assert_eq!(b.levels, planes(&(0..15).collect::<Vec<_>>()));
        let dev = b.to_device(&Device::flex());
        assert_eq!(dev.features.dims(), [1, 15, 2, 2]);
        assert_eq!(dev.levels.dims(), [1, 6, 2, 2]);
    }

    #[test]
    fn epoch_plan_is_a_seeded_permutation() {
        let ds = PatchDataset::from_samples(vec![ramp_sample(8, 8), ramp_sample(6, 8)], 4, 2);
        let a = ds.epoch_plan(7, 3);
        assert_eq!(a, ds.epoch_plan(7, 3));
        assert_ne!(a, ds.epoch_plan(7, 4));
        assert_eq!(a.len(), ds.patches_per_epoch());
        let mut keys: Vec<_> = a.iter().map(|p| (p.image, p.x, p.y)).collect();
        keys.sort();
        keys.dedup();
        assert_eq!(keys.len(), a.len());
    }
}
