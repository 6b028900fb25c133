//! Everything that crosses into C++ (the one cxx bridge, [`ffi`], is private
//! to this folder) and the file formats: meshes in (OpenMesh, OBJ in Rust) and
//! out (PLY, glTF binary), level files (OpenVDB), and `info` on any of them.

pub(crate) mod ffi;
pub mod glb;
pub mod info;
pub mod mesh;
pub mod poisson;
mod mesh_check;
pub(crate) mod obj;
pub mod probe;
pub mod vdb;
