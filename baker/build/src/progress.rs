//! Progress reporting of a bake (a leaf module, so that every step can report).

/// Receives a line for each stage of a bake ("weld: 871,414 triangles", "level 3: …"), for
/// progress displays. Called from the baking thread.
pub type Progress<'a> = &'a (dyn Fn(&str) + Sync);
