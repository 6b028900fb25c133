//! Builds the one cxx bridge and its C++ shims, and gives the binary an rpath
//! to libtorch. Reruns only when the bridge or the C++ changes, so Rust edits
//! never recompile the (slow) OpenVDB/CGAL translation units. Also names the
//! font file that the loss plots embed.

use std::path::Path;

const CPP_FILES: &[&str] = &[
    "cpp/mesh_io.cpp",
    "cpp/mesh_decimate.cpp",
    "cpp/vdb_io.cpp",
    "cpp/vdb_guard.cpp",
    "cpp/vdb_points.cpp",
    "cpp/recon_poisson.cpp",
];

fn main() {
    let mut build = cxx_build::bridge("src/io/ffi.rs");
    build
        .files(CPP_FILES)
        .std("c++17")
        // Always optimise the C++: OpenVDB/CGAL code is many times slower at -O0,
        // and ccache keeps the cost to the first build.
        .opt_level(2)
        // No C++ debug information: OpenVDB's and CGAL's templates made it
        // 270 MB of every 280 MB test binary (7.7 GB of target/ for one
        // `cargo test` build, and linkers killed by SIGBUS on a full disk).
        // Rust frames keep their line tables (profile.release debug = 1).
        .debug(false)
        .include("/usr/include/eigen3")
        // One NDEBUG for every translation unit: the C++ files instantiate
        // the same OpenMesh templates, and a macro that changes their bodies
        // in some files and not others breaks the one definition rule.
        // NDEBUG turns off OpenMesh's, Eigen's and Boost's debug assertions
        // (a third of the decimater's time went to OpenMesh's property-name
        // checks); CGAL_DEBUG keeps CGAL's preconditions and assertions,
        // which throw (CGAL's default behaviour) and reach Rust as errors,
        // where NDEBUG alone would make a violated precondition undefined
        // behaviour.
        .define("NDEBUG", None)
        .define("CGAL_DEBUG", None)
        .define("CGAL_EIGEN3_ENABLED", None)
        .define("CGAL_LINKED_WITH_TBB", None)
        .flag_if_supported("-Wno-deprecated-declarations")
        .flag_if_supported("-Wno-unused-parameter");
    build.compile("shapeshifter_cpp");

    // OpenMeshTools: the decimater's observer (cpp/mesh_decimate.cpp).
    for lib in ["openvdb", "tbb", "Imath-3_1", "OpenMeshCore", "OpenMeshTools", "mpfr", "gmp", "blosc"] {
        println!("cargo:rustc-link-lib={lib}");
    }
    // The .vdb probe program uses only cpp/vdb_guard.cpp and its own
    // cpp/vdb_probe_main.cpp (the C entry point and the allocation cap's
    // operator new, which no other program links), not the library crate, so
    // it links neither libtorch (whose start-up alone costs about 0.25 s per
    // process) nor the bridge.
    let out_dir = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    cc::Build::new()
        .cpp(true)
        .file("cpp/vdb_probe_main.cpp")
        .include(Path::new(&out_dir).join("cxxbridge/crate"))
        .std("c++17")
        .opt_level(2)
        .debug(false)
        .define("NDEBUG", None)
        .flag_if_supported("-Wno-deprecated-declarations")
        .cargo_metadata(false)
        .compile("shapeshifter_probe");
    for arg in [format!("-L{out_dir}"), "-lshapeshifter_probe".into(), "-lshapeshifter_cpp".into(), "-lopenvdb".into(), "-ltbb".into(), "-lImath-3_1".into(), "-lblosc".into(), "-lstdc++".into()] {
        println!("cargo:rustc-link-arg-bin=shapeshifter-vdb-probe={arg}");
    }
    // Assimp (FBX, COLLADA, ...) only in its converter program, a static
    // library of its own that nothing else links (no cargo metadata).
    cc::Build::new()
        .cpp(true)
        .file("cpp/assimp_convert.cpp")
        .std("c++17")
        .opt_level(2)
        .debug(false)
        .define("NDEBUG", None)
        .cargo_metadata(false)
        .compile("shapeshifter_assimp");
    for arg in [format!("-L{out_dir}"), "-lshapeshifter_assimp".into(), "-lassimp".into(), "-lstdc++".into()] {
        println!("cargo:rustc-link-arg-bin=shapeshifter-assimp={arg}");
    }
    println!("cargo:rerun-if-changed=src/io/ffi.rs");
    println!("cargo:rerun-if-changed=cpp");
    for f in CPP_FILES {
        println!("cargo:rerun-if-changed={f}");
    }

    // libtorch's lib folder, from torch-sys (links = "tch"), else $LIBTORCH/lib.
    let torch_lib = std::env::var("DEP_TCH_LIBTORCH_LIB").ok().or_else(|| {
        std::env::var("LIBTORCH").ok().map(|d| format!("{d}/lib"))
    });
    if let Some(dir) = torch_lib {
        let dir = Path::new(&dir).canonicalize().unwrap_or_else(|_| dir.clone().into());
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    }
    if std::env::var("CARGO_FEATURE_CUDA").is_ok() {
        // rustc links with --as-needed, which would drop libtorch_cuda.
        println!("cargo:rustc-link-arg=-Wl,--push-state,--no-as-needed,-ltorch_cuda,--pop-state");
    }
    println!("cargo:rerun-if-env-changed=LIBTORCH");

    plot_font();
}

/// The TrueType font the loss plots' text is drawn with (src/learn/train/plot.rs
/// embeds its bytes, so the program needs no font, nor fontconfig, at run time):
/// $SHAPESHIFTER_PLOT_FONT, else DejaVu Sans from the Debian package
/// fonts-dejavu-core (installed by make setup).
fn plot_font() {
    const DEBIAN: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
    println!("cargo:rerun-if-env-changed=SHAPESHIFTER_PLOT_FONT");
    let path = std::env::var("SHAPESHIFTER_PLOT_FONT").unwrap_or_else(|_| DEBIAN.to_string());
    if !Path::new(&path).is_file() {
        panic!(
            "the loss plots' font {path} is missing: install the Debian package fonts-dejavu-core \
             (make setup does: scripts/setup.sh), or set SHAPESHIFTER_PLOT_FONT to a .ttf file"
        );
    }
    let path = Path::new(&path).canonicalize().expect("font path");
    println!("cargo:rerun-if-changed={}", path.display());
    println!("cargo:rustc-env=SHAPESHIFTER_PLOT_FONT={}", path.display());
}
