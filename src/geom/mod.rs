//! Geometry shared by several stages.

pub mod nearest;
