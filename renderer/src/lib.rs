//! Physically based renderer: Mitsuba 3 XML scenes, BVH, materials, lights, cameras, a path
//! tracer and the multi-level SPPM integrator that writes sample bundles.
//! It knows nothing of neural networks.
//!
//! What exists only for parity with Mitsuba 3 (participating media and `volpath`, the `aov`,
//! `depth` and `direct` integrators, Mitsuba 0.x scene files) is grouped in [`parity`], off the
//! pipeline's path.

pub mod accel;
pub mod bsdf;
pub mod camera;
pub mod description;
pub mod film;
pub mod filter;
pub mod frame;
pub mod image_io;
pub mod integrators;
pub mod lights;
pub mod math;
pub mod memory;
pub mod parity;
pub mod sampling;
pub mod scene;
pub mod scene_file;
pub mod shapes;
pub mod spectrum;
pub mod state_file;
#[cfg(test)]
mod test_data;
pub mod texture;
pub mod threads;
pub mod xml;
