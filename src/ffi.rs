//! The one cxx bridge to the C++ side (OpenVDB, OpenMesh, CGAL). Nothing here
//! but declarations: the safe wrappers live in `mesh`, `vdb` and `recon`.
//! Every function that can throw returns `Result`, so a C++ exception becomes
//! an `Err` instead of `std::terminate`. Arrays cross the bridge in bulk.

#[cxx::bridge(namespace = "shapeshifter")]
pub mod bridge {
    /// A mesh as flat arrays, as read by OpenMesh (polygons fan-triangulated).
    #[derive(Default)]
    pub struct MeshData {
        /// 3 floats per vertex.
        pub positions: Vec<f32>,
        /// 3 vertex indices per triangle.
        pub triangles: Vec<u32>,
        /// 3 floats in [0,1] per vertex, or empty.
        pub vertex_colours: Vec<f32>,
        /// 3 floats in [0,1] per triangle (OBJ material Kd), or empty.
        pub face_colours: Vec<f32>,
        /// 2 floats per triangle corner, or empty.
        pub corner_uvs: Vec<f32>,
        /// Texture index per triangle (into `texture_files`), or empty.
        pub face_texture: Vec<i32>,
        /// Texture file names as written in the material file, by index.
        pub texture_ids: Vec<i32>,
        pub texture_files: Vec<String>,
        /// Faces the reader dropped (repeated vertices, invalid indices).
        pub faces_in_file: u64,
    }

    /// Typed metadata entries, stored on every grid of a level file.
    pub struct MetaEntry {
        pub key: String,
        /// "string", "int", "float" or "vec3d"
        pub kind: String,
        pub text: String,
        pub number: f64,
        pub vec: [f64; 3],
    }

    /// One level as flat arrays: OpenVDB index coordinates and the features at
    /// each voxel. World transform: voxel (i,j,k)'s centre is at
    /// `origin + (i,j,k) * voxel_size` in the exemplar's frame (world units).
    pub struct LevelData {
        pub coords: Vec<i32>,
        /// world positions P, 3 per voxel
        pub points: Vec<f32>,
        pub normals: Vec<f32>,
        pub colours: Vec<f32>,
        pub mask: Vec<f32>,
        pub voxel_size: f64,
        pub origin: [f64; 3],
        pub meta: Vec<MetaEntry>,
    }

    /// What `vdb_print -l -m` would say about one grid.
    pub struct GridSummary {
        pub name: String,
        pub value_type: String,
        pub grid_class: String,
        pub vector_type: String,
        pub active_voxels: u64,
        /// index-space active bounding box, min then max
        pub bbox: [i32; 6],
        pub voxel_size: [f64; 3],
        pub origin: [f64; 3],
        pub point_count: u64,
        pub attributes: Vec<String>,
        pub meta: Vec<MetaEntry>,
    }

    unsafe extern "C++" {
        include!("shapeshifter/cpp/mesh_io.h");
        fn read_mesh(path: &str) -> Result<MeshData>;
        fn write_mesh(path: &str, mesh: &MeshData, binary: bool) -> Result<()>;

        include!("shapeshifter/cpp/vdb_io.h");
        fn write_level_file(path: &str, level: &LevelData, half_floats: bool) -> Result<()>;
        fn read_level_file(path: &str) -> Result<LevelData>;
        fn summarise_vdb_file(path: &str) -> Result<Vec<GridSummary>>;
    }
}
