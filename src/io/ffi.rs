//! The one cxx bridge to the C++ side (OpenVDB, OpenMesh, CGAL). Nothing here
//! but declarations: the safe wrappers are this folder's `mesh`, `vdb` and
//! `poisson`, the only modules that use it.
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
        /// Faces OpenMesh read from the file and kept (polygons before
        /// triangulation): fewer than the header declares when it skipped
        /// some (repeated vertices, invalid indices, non-manifold edges).
        pub faces_in_file: u64,
    }

    /// Parameters of the quadric decimation (`decimate_mesh`).
    #[derive(Clone, Debug)]
    pub struct DecimateParams {
        /// Stop when this many triangles remain (or no collapse is legal).
        pub target_faces: u64,
        /// Edges whose faces' normals differ by more than this (degrees) are
        /// sharp features: kept as lines, their corners fixed.
        pub feature_angle_deg: f64,
        /// A collapse may turn a nearby face's normal by at most this (degrees).
        pub max_normal_deviation_deg: f64,
    }

    /// A decimated triangle mesh as flat arrays.
    #[derive(Clone, Debug, Default)]
    pub struct DecimatedMesh {
        /// 3 floats per vertex.
        pub positions: Vec<f32>,
        /// 3 vertex indices per triangle, in the input's orientation.
        pub triangles: Vec<u32>,
        /// For each vertex, the input vertex it is (collapses never move a
        /// survivor), to carry per-vertex data such as colours.
        pub source_vertex: Vec<u32>,
        /// Edges marked as sharp features before decimating.
        pub feature_edges: u64,
    }

    /// The value type of a metadata entry (OpenVDB's string, int64, double
    /// and vec3d metadata; others read back as text).
    #[derive(Debug)]
    pub enum MetaKind {
        Text,
        Int,
        Float,
        Vec3,
    }

    /// Typed metadata entries, stored on every grid of a level file.
    pub struct MetaEntry {
        pub key: String,
        /// Which of `text`, `number` or `vec` holds the value.
        pub kind: MetaKind,
        pub text: String,
        pub number: f64,
        pub vec: [f64; 3],
    }

    /// One level as flat arrays: OpenVDB index coordinates and the features at
    /// each voxel. World transform: voxel (i,j,k)'s centre is at
    /// `origin + (i,j,k) * voxel_size` in the exemplar's frame (world units).
    pub struct LevelData {
        pub coords: Vec<i32>,
        /// world positions P, 3 per voxel (f64: georeferenced coordinates
        /// in the millions of metres keep their centimetres)
        pub points: Vec<f64>,
        /// Write P as vec3d (float32 would round the positions by more than
        /// a 64th of a voxel); read: P was vec3d.
        pub double_positions: bool,
        pub normals: Vec<f32>,
        pub colours: Vec<f32>,
        pub mask: Vec<f32>,
        pub voxel_size: f64,
        pub origin: [f64; 3],
        pub meta: Vec<MetaEntry>,
        /// Read only: voxels active in P, N or Cd but not in the mask (not
        /// part of the level; a file edited by another tool may have them).
        pub unmatched_voxels: u64,
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

    /// Parameters of CGAL's Poisson reconstruction, in world units.
    #[derive(Clone, Debug)]
    pub struct PoissonParams {
        /// Sample spacing in world units; <= 0: CGAL's average spacing (6 neighbours).
        pub spacing: f64,
        /// Conjugate gradient: relative residual; <= 0: Eigen's default (machine epsilon).
        pub solver_tolerance: f64,
        /// Conjugate gradient: iteration cap; 0: Eigen's default (2 x unknowns).
        pub solver_max_iterations: u32,
        /// Grid cell of `poisson_grid`, world units.
        pub grid_cell: f64,
    }

    /// Where the time went (process CPU seconds), and how big things got.
    #[derive(Clone, Debug, Default)]
    pub struct PoissonStats {
        /// The spacing actually used (world units).
        pub spacing: f64,
        /// Vertices of the refined Delaunay triangulation (= unknowns + 1).
        pub delaunay_vertices: u64,
        pub solver_iterations: u64,
        /// Relative residual reached by the solver.
        pub solver_error: f64,
        /// Average spacing + first Delaunay insertion.
        pub seconds_setup: f64,
        /// Delaunay insertion of the input interleaved with refinement, and assembly.
        pub seconds_refine: f64,
        /// Sparse linear solve.
        pub seconds_solve: f64,
        /// The grid evaluation of `poisson_grid`.
        pub seconds_mesh: f64,
        /// Surface nets on the sampled grid (filled in on the Rust side, wall clock).
        pub seconds_output: f64,
        /// Grid corners evaluated by `poisson_grid`.
        pub grid_corners: u64,
    }

    /// The Poisson function sampled on a sparse grid: bricks of 8^3 corners
    /// around its zero set. Corner (i, j, k) lies at origin + (i, j, k) * cell.
    #[derive(Clone, Debug, Default)]
    pub struct PoissonGrid {
        /// 3 ints per brick; brick b holds corners 8b .. 8b + 7 on each axis.
        pub bricks: Vec<i32>,
        /// 512 values per brick, corner (x, y, z) of the brick at (x * 8 + y) * 8 + z;
        /// negative inside, NaN where not evaluated (away from the zero set).
        pub values: Vec<f32>,
        pub origin: [f64; 3],
        pub cell: f64,
        pub stats: PoissonStats,
    }

    unsafe extern "C++" {
        include!("shapeshifter/cpp/mesh_io.h");
        fn read_mesh(path: &str) -> Result<MeshData>;
        fn write_mesh(path: &str, mesh: &MeshData, binary: bool) -> Result<()>;

        include!("shapeshifter/cpp/mesh_decimate.h");
        /// Quadric-error decimation (OpenMesh); `positions` 3 floats per
        /// vertex, `triangles` 3 indices per triangle.
        fn decimate_mesh(
            positions: &[f32],
            triangles: &[u32],
            params: &DecimateParams,
        ) -> Result<DecimatedMesh>;

        include!("shapeshifter/cpp/vdb_io.h");
        /// `volumes`: grids mask, density, P, N, Cd; `points`: the PointDataGrid.
        fn write_level_file(path: &str, level: &LevelData, half_floats: bool, volumes: bool, points: bool)
            -> Result<()>;
        fn read_level_file(path: &str) -> Result<LevelData>;
        fn summarise_vdb_file(path: &str) -> Result<Vec<GridSummary>>;

        include!("shapeshifter/cpp/recon_poisson.h");
        /// Poisson reconstruction through CGAL (unscreened, Delaunay-based):
        /// the implicit function sampled on a sparse grid of cell
        /// `params.grid_cell` around its whole zero set (for surface nets);
        /// `points` and `normals` hold 3 floats per point (normals outwards).
        fn poisson_grid(points: &[f32], normals: &[f32], params: &PoissonParams)
            -> Result<PoissonGrid>;
    }
}
