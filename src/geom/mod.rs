//! Geometry shared by several stages.

pub mod colour;
pub mod edges;
pub mod nearest;
pub mod normals;
pub mod points;
pub mod splat;
pub mod texture;
