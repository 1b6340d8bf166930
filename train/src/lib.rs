//! Training of the combiner network (docs/method.md, "Training"): the train TOML ([`config`]),
//! the patch dataset read from a `datagen` dataset ([`data`]), the training loop
//! ([`training`]), checkpoints and resume ([`checkpoint`]) and the learning curves
//! ([`curves`]). The network itself is the `model` crate's.

pub mod checkpoint;
pub mod config;
pub mod curves;
pub mod data;
pub mod training;
