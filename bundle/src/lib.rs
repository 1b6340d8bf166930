//! The sample-bundle format (SPEC §3.5): the contract between the renderer and the network side.
