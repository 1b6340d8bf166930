//! Light transport algorithms: each integrator turns a scene into images.

pub mod direct;
pub mod path;
pub mod ray_integrator;
pub mod sppm;
pub mod volpath;

pub use ray_integrator::RayIntegrator;
