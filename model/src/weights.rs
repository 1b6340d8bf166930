//! Weight files of the network: Burn's burnpack (`model.bpk`, what the toolkit loads) and
//! safetensors (`model.safetensors`, for other tools), written atomically and byte-for-byte
//! reproducible — Burn writes some maps in hash order, so headers and optimizer states are put
//! into a canonical (sorted) order here — and loaded strictly: a file whose tensors do not fit
//! the architecture exactly is refused, naming it.

use std::path::Path;

use burn::optim::ModuleOptimizer;
use burn::store::{BurnpackStore, ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;
use fileio::atomic::{temp_path, write_with};

use crate::network::{ModelConfig, Network};

/// Saves a module as burnpack, atomically (temp file + rename).
pub fn save_burnpack(model: &Network, path: &Path) -> Result<(), String> {
    write_with(path, |tmp| {
        let mut store = BurnpackStore::from_file(tmp)
            .auto_extension(false)
            .overwrite(true);
        model.save_into(&mut store).map_err(|e| e.to_string())
    })
    .map_err(|e| format!("{}: {}", path.display(), e.into_error(|e| e.to_string())))
}

/// Saves a module as safetensors, atomically, with its header in a canonical order.
pub fn save_safetensors(model: &Network, path: &Path) -> Result<(), String> {
    write_with(path, |tmp| {
        let mut store = SafetensorsStore::from_file(tmp);
        model.save_into(&mut store).map_err(|e| e.to_string())?;
        canonical_safetensors_header(tmp)
    })
    .map_err(|e| format!("{}: {}", path.display(), e.into_error(|e| e.to_string())))
}

/// Rewrites a safetensors file's JSON header with its keys sorted. Burn writes the
/// `__metadata__` entries from a hash map, in an order that changes from run to run, so the
/// same weights would give different files. The tensor entries name their byte ranges, so their
/// order is free; the header keeps its length (padded with spaces, as the format allows), so the
/// tensor data is not moved.
pub fn canonical_safetensors_header(path: &Path) -> Result<(), String> {
    let mut bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let len_bytes: [u8; 8] = bytes
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or("not a safetensors file (shorter than its header length)")?;
    let len = usize::try_from(u64::from_le_bytes(len_bytes)).map_err(|e| e.to_string())?;
    let header = bytes
        .get(8..8 + len)
        .ok_or("not a safetensors file (header longer than the file)")?;
    let value: serde_json::Value =
        serde_json::from_slice(header).map_err(|e| format!("safetensors header: {e}"))?;
    let mut sorted = serde_json::to_vec(&sort_keys(value)).map_err(|e| e.to_string())?;
    if sorted.len() > len {
        return Err("safetensors header grew when sorted".into());
    }
    sorted.resize(len, b' ');
    bytes[8..8 + len].copy_from_slice(&sorted);
    std::fs::write(path, bytes).map_err(|e| e.to_string())
}

/// Saves an optimizer's state (`optimizer.bpk` of a checkpoint) atomically, its tensors in name
/// order ([`sorted_burnpack`]).
pub fn save_optimizer(optim: &ModuleOptimizer, path: &Path) -> Result<(), String> {
    let raw = temp_path(&path.with_file_name("optimizer.raw.bpk"));
    let saved = optim
        .save(&raw)
        .map_err(|e| format!("{e:?}"))
        .and_then(|()| {
            write_with(path, |tmp| sorted_burnpack(&raw, tmp))
                .map_err(|e| e.into_error(|e| e.to_string()))
        });
    let _ = std::fs::remove_file(&raw);
    saved.map_err(|e| format!("{}: {e}", path.display()))
}

/// Writes the burnpack file `from` to `to` with its tensors in name order. Burn's optimizer
/// lists its per-parameter state in hash-map order, which changes from run to run, so the same
/// training would otherwise write different checkpoint files. (Scalars and metadata are kept in
/// maps ordered by key already.)
fn sorted_burnpack(from: &Path, to: &Path) -> Result<(), String> {
    let reader = burn_pack::Reader::from_file_exact(from).map_err(|e| e.to_string())?;
    let scalars = reader.scalars().clone();
    let metadata = reader.metadata().clone();
    let mut tensors = reader.into_tensors().map_err(|e| e.to_string())?;
    tensors.sort_by(|a, b| a.name.cmp(&b.name));
    let mut writer = burn_pack::Writer::new(tensors)
        .auto_extension(false)
        .overwrite(true);
    for (key, value) in &scalars {
        writer = writer.with_scalar(key, *value);
    }
    for (key, value) in &metadata {
        writer = writer.with_metadata(key, value);
    }
    writer.write_to_file(to).map_err(|e| e.to_string())
}

/// `value` with the keys of every object in sorted order (whatever order serde_json's map
/// keeps, which depends on its `preserve_order` feature).
fn sort_keys(value: serde_json::Value) -> serde_json::Value {
    match value {
        serde_json::Value::Object(map) => {
            let sorted: std::collections::BTreeMap<String, serde_json::Value> =
                map.into_iter().map(|(k, v)| (k, sort_keys(v))).collect();
            serde_json::Value::Object(sorted.into_iter().collect())
        }
        serde_json::Value::Array(items) => {
            serde_json::Value::Array(items.into_iter().map(sort_keys).collect())
        }
        other => other,
    }
}

/// Loads burnpack weights into a freshly built network of `config`.
pub fn load_burnpack(
    config: &ModelConfig,
    path: &Path,
    device: &Device,
) -> Result<Network, String> {
    if !path.exists() {
        return Err(format!("{}: no such file", path.display()));
    }
    let mut model = config.init(0, device);
    let mut store = BurnpackStore::from_file(path).auto_extension(false);
    let result = model
        .load_from(&mut store)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if !result.is_success() || !result.missing.is_empty() {
        return Err(format!(
            "{}: weights do not match the model config: {result:?}",
            path.display()
        ));
    }
    // Tensors the network has no place for (a deeper network's extra layers) are not ignored.
    if !result.unused.is_empty() {
        return Err(format!(
            "{}: weights do not match the model config: the file holds {} that a network of \
             {} hidden layers does not have",
            path.display(),
            result.unused.join(", "),
            config.hidden_layers
        ));
    }
    Ok(model)
}
