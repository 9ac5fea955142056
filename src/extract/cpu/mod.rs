//! The CPU twin of every GPU stage, one file per shader, in plain Rust (rayon over rows).

pub mod canny;
pub mod diffusion;
pub mod normals;
pub mod ransac;
