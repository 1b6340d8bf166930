//! Stochastic progressive photon mapping with five nested kernel bandwidths (SPEC §3.4), and
//! its single-level baseline.

pub mod accumulate;
pub mod photon_map;
pub mod radius;
