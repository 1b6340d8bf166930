//! Light transport algorithms: each integrator turns a scene into images.

pub mod path;
pub mod sppm;
