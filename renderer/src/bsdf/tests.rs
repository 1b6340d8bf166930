//! Statistical tests of every BSDF (see the module doc of `bsdf`).
