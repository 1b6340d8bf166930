//! Physically based renderer: Mitsuba 3 XML scenes, BVH, materials, lights, cameras, a path
//! tracer and the multi-level SPPM integrator that writes sample bundles.
//! It knows nothing of neural networks.

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
pub mod media;
pub mod memory;
pub mod sampling;
pub mod scene;
pub mod shapes;
pub mod spectrum;
pub mod state_file;
#[cfg(test)]
mod test_data;
pub mod texture;
pub mod xml;
