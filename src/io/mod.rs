//! Everything that crosses into C++ (the one cxx bridge, [`ffi`], is
//! `pub(crate)` for its plain data types, e.g. the mesh arrays `obj` fills, and
//! called only from this folder) and the file formats: exemplars in (meshes through OpenMesh,
//! OBJ and glTF in Rust; point clouds: PLY, LAS/LAZ, E57) and
//! out (PLY, glTF binary), level files (OpenVDB), and `info` on any of them.

pub mod assimp;
pub mod cloud;
pub mod dataset;
pub mod exemplar;
pub(crate) mod ffi;
pub mod glb;
pub mod helper;
pub(crate) mod gltf_read;
pub mod info;
pub mod mesh;
pub mod mesh_data;
pub mod poisson;
pub(crate) mod mesh_check;
pub(crate) mod obj;
pub mod probe;
pub mod settings;
pub mod usd;
pub mod vdb;
