//! Parts of the renderer that exist only for parity with Mitsuba 3, off the pipeline's path.
//!
//! The pipeline (SPPM, dataset generation, `infer --scene`) needs the XML reader, shapes,
//! BSDFs, emitters, cameras, filters, the path tracer and SPPM. What is here is not on that
//! path: it lets `render` read and render the Mitsuba scenes the renderer is validated
//! against (docs/validation.md):
//! - [`media`]: participating media (homogeneous and grid media, phase functions), which only
//!   [`volpath`] renders (the scene and the XML reader refer to them: a shape's or the
//!   camera's medium);
//! - [`volpath`]: the volumetric path tracer (Mitsuba's `volpath`);
//! - [`aov`]: the `aov` and `depth` integrators (arbitrary output variables, distances);
//! - [`direct`]: the `direct` integrator (direct illumination only);
//! - [`upgrade`]: reading scene files written for Mitsuba 0.x (`version` < 2).
//!
//! New features come here only when the pipeline needs them.

pub mod aov;
pub mod direct;
pub mod media;
pub mod upgrade;
pub mod volpath;
