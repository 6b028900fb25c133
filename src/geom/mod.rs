//! Geometry shared by several stages.

pub mod edges;
pub mod nearest;
pub mod normals;
pub mod points;
pub mod texture;
