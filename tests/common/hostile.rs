//! The mutation harness for hostile files, shared by `tests/hostile.rs` (a
//! fixed, bounded count in `make test`) and `tools/hostile_campaign.rs` (long
//! campaigns with a count and a seed).
//!
//! 1. Seed inputs are generated (a small coloured sphere in every mesh format,
//!    an OBJ with its MTL and PNG texture, a small level file), or taken from
//!    files the caller names.
//! 2. Each run mutates ONE file of a seed input the way disks, transfers and
//!    other tools mangle files (bytes overwritten, truncation, a field replaced by
//!    a huge or negative integer, a chunk duplicated), from a fixed seed, and runs
//!    the real binary on it.
//! 3. The verdict: the child ended with exit 0, or with exit 1 and one line
//!    starting `error` (no signal, no panic); it wrote nothing on failure; it
//!    finished within the time limit; its peak RSS (VmHWM of the child,
//!    sampled every few ms) stayed under the stated bound. A watchdog kills a child
//!    whose RSS passes a hard ceiling, so a regression cannot take the machine
//!    down before the bound is checked.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use glam::{IVec3, Vec2, Vec3};
use shapeshifter::util::rng::Rng;

/// The memory bound every run must keep: peak RSS at most the binary's own
/// peak on the same, intact input (plus 64 MiB of slack for the allocator and
/// error paths) plus 64 times the size of the input file.
pub const RSS_SLACK_BYTES: u64 = 64 << 20;
pub const RSS_PER_INPUT_BYTE: u64 = 64;
/// A child whose RSS passes this is killed at once (counted as a failure).
pub const RSS_CEILING_BYTES: u64 = 3 << 30;

/// One input set: the files (name, bytes) laid out together in a folder, which
/// of them may be mutated, and the commands to run (`{in}` is the main file,
/// `{out}` an empty output folder).
#[derive(Clone)]
pub struct Seed {
    pub format: String,
    pub files: Vec<(String, Vec<u8>)>,
    /// Indices into `files` that mutations pick from.
    pub mutable: Vec<usize>,
    pub commands: Vec<Vec<String>>,
}

impl Seed {
    fn main_file(&self) -> &str {
        &self.files[0].0
    }
}

fn args(a: &[&str]) -> Vec<String> {
    a.iter().map(|s| s.to_string()).collect()
}

/// A small sphere (a few hundred triangles) with vertex colours.
pub fn small_sphere() -> shapeshifter::io::mesh::Mesh {
    let mut m = shapeshifter::testing::shapes::uv_sphere(Vec3::ZERO, 10, 14, |th, ph| 1.0 + 0.2 * (3.0 * ph).sin() * th.sin());
    let colours = m.positions.iter().map(|p| (*p * 0.4 + 0.5).clamp(Vec3::ZERO, Vec3::ONE)).collect();
    m.colours = shapeshifter::io::mesh::MeshColours::PerVertex(colours);
    m
}

fn saved(mesh: &shapeshifter::io::mesh::Mesh, dir: &Path, name: &str, binary: bool) -> Vec<u8> {
    let p = dir.join(name);
    shapeshifter::io::mesh::save(mesh, &p, binary).expect("seed mesh writes");
    std::fs::read(&p).expect("seed mesh reads back")
}

/// An OBJ with UVs, two materials (one textured, one with a Kd colour), its
/// MTL and an 8x8 PNG texture: every part of the OBJ reader's path.
pub fn textured_obj(mesh: &shapeshifter::io::mesh::Mesh) -> Vec<(String, Vec<u8>)> {
    let mut obj = String::from("# shapeshifter hostile-input seed\nmtllib seed.mtl\no sphere\n");
    for p in &mesh.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for p in &mesh.positions {
        let uv = Vec2::new(p.x.atan2(p.y) / std::f32::consts::TAU + 0.5, p.z * 0.5 + 0.5);
        obj += &format!("vt {} {}\n", uv.x, uv.y);
    }
    let half = mesh.triangles.len() / 2;
    obj += "usemtl textured\n";
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if t == half {
            obj += "usemtl plain\n";
        }
        let [a, b, c] = tri.map(|i| i + 1);
        obj += &format!("f {a}/{a} {b}/{b} {c}/{c}\n");
    }
    let mtl = "newmtl textured\nKd 1 1 1\nmap_Kd seed.png\n\nnewmtl plain\nKd 0.8 0.3 0.1\n";
    let img = image::RgbImage::from_fn(8, 8, |x, y| image::Rgb([(x * 32) as u8, (y * 32) as u8, 128]));
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).expect("png encodes");
    vec![("seed.obj".into(), obj.into_bytes()), ("seed.mtl".into(), mtl.into()), ("seed.png".into(), png)]
}

/// A glTF with its buffer and PNG texture beside it (base colour factor,
/// texture with a sampler, UVs, indices): every part of the glTF reader's path.
pub fn textured_gltf(mesh: &shapeshifter::io::mesh::Mesh) -> Vec<(String, Vec<u8>)> {
    let mut bin = Vec::new();
    for p in &mesh.positions {
        p.to_array().iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    }
    let uv_at = bin.len();
    for p in &mesh.positions {
        [p.x.atan2(p.y) / std::f32::consts::TAU + 0.5, p.z * 0.5 + 0.5].iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    }
    let idx_at = bin.len();
    for v in mesh.triangles.iter().flatten() {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let (lo, hi) = mesh.bounds();
    let n = mesh.positions.len();
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
"nodes":[{{"mesh":0,"translation":[1,2,3]}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1}},"indices":2,"material":0}}]}}],
"materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[1,0.8,0.6,1],"baseColorTexture":{{"index":0}}}}}}],
"textures":[{{"source":0,"sampler":0}}],"samplers":[{{"wrapS":33648,"wrapT":33071}}],"images":[{{"uri":"seed.png"}}],
"buffers":[{{"uri":"seed.bin","byteLength":{len}}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{uv_at}}},{{"buffer":0,"byteOffset":{uv_at},"byteLength":{uvl}}},{{"buffer":0,"byteOffset":{idx_at},"byteLength":{il}}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":{n},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},
{{"bufferView":1,"componentType":5126,"count":{n},"type":"VEC2"}},
{{"bufferView":2,"componentType":5125,"count":{ni},"type":"SCALAR"}}]}}"#,
        lo.x, lo.y, lo.z, hi.x, hi.y, hi.z,
        len = bin.len(),
        uvl = idx_at - uv_at,
        il = bin.len() - idx_at,
        ni = 3 * mesh.triangles.len(),
    );
    let img = image::RgbImage::from_fn(8, 8, |x, y| image::Rgb([(x * 32) as u8, (y * 32) as u8, 128]));
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).expect("png encodes");
    vec![("seed.gltf".into(), json.into_bytes()), ("seed.bin".into(), bin), ("seed.png".into(), png)]
}

/// Points on the small sphere (its vertices, a few hundred) with colours.
fn cloud_points(mesh: &shapeshifter::io::mesh::Mesh) -> (Vec<glam::DVec3>, Vec<Vec3>) {
    let p: Vec<glam::DVec3> = mesh.positions.iter().map(|p| p.as_dvec3() * 10.0 + glam::DVec3::new(1000.0, 2000.0, 50.0)).collect();
    let c = mesh.positions.iter().map(|p| (*p * 0.4 + 0.5).clamp(Vec3::ZERO, Vec3::ONE)).collect();
    (p, c)
}

/// A level of about `n` voxels on a sphere of radius 20 voxels.
pub fn sphere_level(n: usize) -> shapeshifter::level::Level {
    let mut level = shapeshifter::level::Level { index: 1, resolution: 64, ..Default::default() };
    let mut seen = std::collections::HashSet::new();
    for i in 0..n * 4 {
        let y = 1.0 - 2.0 * (i as f32 + 0.5) / (n * 4) as f32;
        let phi = i as f32 * 2.399_963;
        let r = (1.0 - y * y).sqrt();
        let d = Vec3::new(r * phi.cos(), y, r * phi.sin());
        let p = d * 20.0;
        let c = p.round().as_ivec3();
        if level.len() < n && seen.insert(c) {
            level.coords.push(c + IVec3::splat(32));
            level.offsets.push((p - c.as_vec3()).clamp(Vec3::splat(-0.5), Vec3::splat(0.5)));
            level.normals.push(d);
            level.colours.push(d * 0.5 + 0.5);
            level.mask.push(1.0);
        }
    }
    level
}

/// The built-in seed inputs: every mesh format and a level file, generated
/// here (no data folder needed). `scratch` is a folder for the writers.
pub fn builtin_seeds(scratch: &Path) -> Vec<Seed> {
    let sphere = small_sphere();
    let info = vec![args(&["info", "{in}"])];
    let mesh_cmds = vec![args(&["info", "{in}"]), args(&["render", "{in}", "-o", "{out}/r.png", "--width", "64", "--height", "64"])];
    let mut seeds = vec![
        Seed { format: "obj+mtl+png".into(), files: textured_obj(&sphere), mutable: vec![0, 0, 0, 1, 2], commands: mesh_cmds.clone() },
        Seed { format: "ply-binary".into(), files: vec![("seed.ply".into(), saved(&sphere, scratch, "b.ply", true))], mutable: vec![0], commands: mesh_cmds.clone() },
        Seed { format: "ply-ascii".into(), files: vec![("seed.ply".into(), saved(&sphere, scratch, "a.ply", false))], mutable: vec![0], commands: info.clone() },
        Seed { format: "off".into(), files: vec![("seed.off".into(), saved(&sphere, scratch, "s.off", false))], mutable: vec![0], commands: info.clone() },
        Seed { format: "stl-binary".into(), files: vec![("seed.stl".into(), saved(&sphere, scratch, "b.stl", true))], mutable: vec![0], commands: info.clone() },
        Seed { format: "stl-ascii".into(), files: vec![("seed.stl".into(), saved(&sphere, scratch, "a.stl", false))], mutable: vec![0], commands: info.clone() },
        Seed { format: "glb".into(), files: vec![("seed.glb".into(), saved(&sphere, scratch, "s.glb", true))], mutable: vec![0], commands: mesh_cmds.clone() },
        Seed { format: "gltf+bin+png".into(), files: textured_gltf(&sphere), mutable: vec![0, 0, 1, 1, 2], commands: mesh_cmds.clone() },
    ];
    // Point clouds: `info` and an encode at the smallest resolutions (the
    // normal estimation and the binning run on whatever was read).
    let encode = args(&["encode", "{in}", "-o", "{out}/e", "--coarsest", "16", "--finest", "16", "--sampling-resolution", "32"]);
    let cloud_cmds = vec![args(&["info", "{in}"]), encode];
    let (p, c) = cloud_points(&sphere);
    let normals: Vec<Vec3> = sphere.vertex_normals();
    let pf: Vec<Vec3> = p.iter().map(|q| q.as_vec3()).collect();
    let ply = scratch.join("points.ply");
    shapeshifter::io::mesh::save_points_ply(&ply, &pf, &normals, &c).expect("seed points write");
    let n = p.len();
    let intensity: Vec<u16> = (0..n).map(|i| (i * 37 % 65536) as u16).collect();
    let classes: Vec<u8> = (0..n).map(|i| [2u8, 5, 6][i % 3]).collect();
    let (las, laz, e57) = (scratch.join("s.las"), scratch.join("s.laz"), scratch.join("s.e57"));
    shapeshifter::testing::clouds::write_las(&las, &p, Some(&c), &intensity, &classes, Some("PROJCS[\"seed\",AUTHORITY[\"EPSG\",\"32632\"]]")).expect("seed LAS writes");
    shapeshifter::testing::clouds::write_las(&laz, &p, None, &intensity, &classes, None).expect("seed LAZ writes");
    let unit: Vec<f32> = intensity.iter().map(|&i| i as f32 / 65535.0).collect();
    shapeshifter::testing::clouds::write_e57(&e57, &p, Some(&c), &unit).expect("seed E57 writes");
    for (format, name, path) in [("ply-points", "seed.ply", &ply), ("las", "seed.las", &las), ("laz", "seed.laz", &laz), ("e57", "seed.e57", &e57)] {
        seeds.push(Seed { format: format.into(), files: vec![(name.into(), std::fs::read(path).expect("seed reads back"))], mutable: vec![0], commands: cloud_cmds.clone() });
    }
    let level_path = scratch.join("level_1.vdb");
    shapeshifter::io::vdb::write_level(
        &level_path,
        &sphere_level(1500),
        &shapeshifter::io::vdb::Provenance::default(),
        shapeshifter::io::vdb::WriteOptions::default(),
    )
    .expect("seed level writes");
    seeds.push(level_seed(std::fs::read(&level_path).expect("seed level reads back")));
    seeds.extend(record_seeds(&sphere, scratch));
    seeds
}

/// A variant's records beside an exemplar and a variant (the exemplar's own
/// levels) for `eval`, which reads each and makes the exemplar again as the
/// variant's start was: bent (`bend.json`), or stretched to a resized box
/// (`extent.json`). The mutations hit the record only.
pub fn record_seeds(sphere: &shapeshifter::io::mesh::Mesh, scratch: &Path) -> Vec<Seed> {
    let config = shapeshifter::config::Config::load(
        "cpu",
        &["encode.coarsest_resolution=16".into(), "encode.finest_resolution=64".into(), "encode.sampling_resolution=128".into()],
    )
    .expect("seed config");
    let ex = scratch.join("record_exemplar");
    let exemplar = shapeshifter::io::exemplar::Exemplar::Mesh(sphere.clone());
    shapeshifter::pipeline::encode_stage(&exemplar, "sphere", "0", &config, &ex).expect("seed exemplar encodes");
    let records = [
        (shapeshifter::level::warp::BEND_FILE, serde_json::to_vec(&shapeshifter::level::warp::Bend { seed: 7, voxels: 2.0 }).expect("bend serialises")),
        (
            shapeshifter::level::resize::EXTENT_FILE,
            serde_json::to_vec(&shapeshifter::level::resize::Extent { extent: [1.25, 1.0, 1.0] }).expect("extent serialises"),
        ),
    ];
    records
        .into_iter()
        .map(|(record, bytes)| {
            let mut files: Vec<(String, Vec<u8>)> = vec![(format!("variant_000/{record}"), bytes)];
            for entry in std::fs::read_dir(&ex).expect("seed exemplar lists").flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                let bytes = std::fs::read(entry.path()).expect("seed exemplar reads");
                if name.starts_with("level_") && name.ends_with(".vdb") && !name.contains("points") {
                    files.push((format!("variant_000/{name}"), bytes.clone()));
                }
                files.push((format!("exemplar/{name}"), bytes));
            }
            Seed {
                format: record.into(),
                files,
                mutable: vec![0],
                commands: vec![args(&["eval", "{indir}/exemplar", "{indir}/variant_000", "-o", "{out}/eval.json"])],
            }
        })
        .collect()
}

/// The level-file commands: every reader path of a level file.
pub fn level_seed(bytes: Vec<u8>) -> Seed {
    Seed {
        format: "vdb".into(),
        files: vec![("level_1.vdb".into(), bytes)],
        mutable: vec![0],
        commands: vec![
            args(&["info", "{in}"]),
            args(&["points", "{in}", "-o", "{out}/p.ply"]),
            args(&["info", "{in}"]),
            args(&["edit", "{in}", "-o", "{out}/e.vdb", "delete", "--box", "0,0,0:40,40,40"]),
            args(&["info", "{in}"]),
            args(&["render", "{in}", "-o", "{out}/r.png", "--width", "64", "--height", "64"]),
        ],
    }
}

/// A seed from a file on disk (with its siblings when it is an OBJ: the MTL
/// and textures it names travel with it, unmutated... or mutated, per `mutable`).
pub fn file_seed(path: &Path) -> std::io::Result<Seed> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    let bytes = std::fs::read(path)?;
    if ext == "vdb" {
        let mut s = level_seed(bytes);
        s.files[0].0 = name;
        s.format = format!("vdb:{}", s.files[0].0);
        return Ok(s);
    }
    Ok(Seed {
        format: format!("{ext}:{name}"),
        files: vec![(name, bytes)],
        mutable: vec![0],
        commands: vec![args(&["info", "{in}"])],
    })
}

/// One mutation, described for the report.
pub fn mutate(input: &[u8], rng: &mut Rng) -> (Vec<u8>, String) {
    let mut b = input.to_vec();
    let len = b.len().max(1);
    match rng.below(10) {
        // Random bytes overwritten (a bad sector, a bit flip, a bad transfer).
        0..=3 => {
            let n = 1 + rng.below(16);
            for _ in 0..n {
                let i = rng.below(len).min(b.len().saturating_sub(1));
                if !b.is_empty() {
                    b[i] = rng.next_u64() as u8;
                }
            }
            (b, format!("overwrite {n} bytes"))
        }
        // Truncation (an interrupted copy or download).
        4 | 5 => {
            let keep = 1 + rng.below(len.saturating_sub(1).max(1));
            b.truncate(keep);
            (b, format!("truncate to {keep}"))
        }
        // A count or size field replaced by a huge, negative or odd integer:
        // four bytes in binary, a number token in text.
        6..=8 => {
            const INTS: [u32; 7] = [0xFFFF_FFFF, 0x7FFF_FFFF, 0x8000_0000, 0x1000_0000, 0x00FF_FFFF, 0x0001_0000, 0];
            let v = INTS[rng.below(INTS.len())];
            if rng.below(2) == 0 && b.len() >= 4 {
                let i = rng.below(b.len() - 3);
                b[i..i + 4].copy_from_slice(&v.to_le_bytes());
                (b, format!("u32 {v:#x} at {i}"))
            } else {
                const TOKENS: [&str; 8] = ["4294967295", "-1", "2000000000", "99999999999999999999", "nan", "1e39", "-2147483648", "0"];
                let t = TOKENS[rng.below(TOKENS.len())];
                // Replace the digit run around a random position, if any.
                let i = rng.below(len).min(b.len().saturating_sub(1));
                let (mut s, mut e) = (i, i);
                while s > 0 && b[s - 1].is_ascii_digit() {
                    s -= 1;
                }
                while e < b.len() && b[e].is_ascii_digit() {
                    e += 1;
                }
                b.splice(s..e, t.bytes());
                (b, format!("token {t} at {s}"))
            }
        }
        // A chunk duplicated elsewhere (a bad merge, a repeated block).
        _ => {
            let s = rng.below(len).min(b.len());
            let n = (1 + rng.below(256)).min(b.len() - s);
            let at = rng.below(len).min(b.len());
            let chunk = b[s..s + n].to_vec();
            b.splice(at..at, chunk);
            (b, format!("duplicate {n} bytes at {at}"))
        }
    }
}

/// What one child run did.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub code: Option<i32>,
    pub signal: Option<i32>,
    pub timed_out: bool,
    pub ceiling_hit: bool,
    pub wall: Duration,
    /// Peak RSS of the child (VmHWM sampled every few ms), bytes.
    pub max_rss: u64,
    pub stderr_bytes: u64,
    pub stderr: String,
}

/// Runs `bin` with `args`, sampling its peak RSS, killing it
/// past `limit` or past the RSS ceiling.
pub fn run_child(bin: &Path, args: &[String], stderr_file: &Path, limit: Duration) -> Outcome {
    let err = std::fs::File::create(stderr_file).expect("stderr file");
    let child = Command::new(bin)
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .expect("binary starts");
    let pid = child.id() as libc::pid_t;
    let start = Instant::now();
    let (mut timed_out, mut ceiling_hit) = (false, false);
    let statm = format!("/proc/{pid}/statm");
    let status_file = format!("/proc/{pid}/status");
    let mut peak = 0u64;
    let page = 4096u64;
    let status = loop {
        let mut status = 0;
        // SAFETY: waits for our own child only.
        let r = unsafe { libc::waitpid(pid, &mut status, libc::WNOHANG) };
        if r == pid {
            break status;
        }
        assert!(r == 0, "waitpid failed: {}", std::io::Error::last_os_error());
        // Peak RSS of the child's own address space (VmHWM), sampled while it
        // runs: wait4's ru_maxrss cannot serve, Linux carries the parent's
        // high-water mark over fork and exec into it.
        if let Some(hwm) = std::fs::read_to_string(&status_file).ok().and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        }) {
            peak = peak.max(hwm * 1024);
        }
        if !timed_out && !ceiling_hit {
            let rss = std::fs::read_to_string(&statm)
                .ok()
                .and_then(|s| s.split_whitespace().nth(1).and_then(|v| v.parse::<u64>().ok()))
                .unwrap_or(0)
                * page;
            if rss > RSS_CEILING_BYTES {
                ceiling_hit = true;
            } else if start.elapsed() > limit {
                timed_out = true;
            }
            if timed_out || ceiling_hit {
                // SAFETY: signals our own child.
                unsafe { libc::kill(pid, libc::SIGKILL) };
            }
        }
        std::thread::sleep(Duration::from_millis(3));
    };
    let wall = start.elapsed();
    let signal = libc::WIFSIGNALED(status).then(|| libc::WTERMSIG(status));
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    Outcome {
        code,
        signal,
        timed_out,
        ceiling_hit,
        wall,
        max_rss: peak,
        stderr_bytes: std::fs::metadata(stderr_file).map(|m| m.len()).unwrap_or(0),
        // The first 64 KiB: a longer stderr breaks the contract by itself.
        stderr: {
            use std::io::Read;
            let mut s = Vec::new();
            let _ = std::fs::File::open(stderr_file).and_then(|f| f.take(64 << 10).read_to_end(&mut s));
            String::from_utf8_lossy(&s).into_owned()
        },
    }
}

/// Why a run broke the contract, if it did.
pub fn verdict(o: &Outcome, leftovers: &[String], rss_bound: u64) -> Option<String> {
    if o.ceiling_hit {
        return Some(format!("RSS passed the {} MiB ceiling", RSS_CEILING_BYTES >> 20));
    }
    if o.timed_out {
        return Some(format!("still running after {:.1} s", o.wall.as_secs_f64()));
    }
    if let Some(s) = o.signal {
        return Some(format!("killed by signal {s}"));
    }
    if o.max_rss > rss_bound {
        return Some(format!("peak RSS {} MiB over the bound {} MiB", o.max_rss >> 20, rss_bound >> 20));
    }
    if o.stderr_bytes > 64 << 10 {
        return Some(format!("{} bytes on stderr", o.stderr_bytes));
    }
    match o.code {
        Some(0) => None,
        Some(1) => {
            let errors: Vec<&str> = o.stderr.lines().filter(|l| l.starts_with("error")).collect();
            if o.stderr.contains("panicked") {
                Some("panicked".into())
            } else if errors.len() != 1 {
                Some(format!("{} error lines", errors.len()))
            } else if !leftovers.is_empty() {
                Some(format!("left output behind: {leftovers:?}"))
            } else {
                None
            }
        }
        c => Some(format!("exit code {c:?}")),
    }
}

/// Per-format figures of a campaign.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    pub runs: usize,
    pub exit0: usize,
    pub exit1: usize,
    pub other_exit: usize,
    pub signals: usize,
    pub timeouts: usize,
    pub ceiling: usize,
    pub worst_wall: Duration,
    pub worst_rss: u64,
    /// (seed index, mutation, command, why) of each run that broke the contract.
    pub failures: Vec<String>,
}

pub struct Campaign {
    pub bin: PathBuf,
    pub seed: u64,
    /// Mutated inputs per seed input.
    pub count: usize,
    pub limit: Duration,
    pub threads: usize,
    /// Where failing inputs are kept (None: not kept).
    pub keep_failures: Option<PathBuf>,
}

fn format_hash(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

/// Lays a seed's files out in `dir`, with file `which` replaced by `bytes`.
fn lay_out(seed: &Seed, dir: &Path, which: usize, bytes: &[u8]) {
    std::fs::create_dir_all(dir).expect("case folder");
    for (i, (name, content)) in seed.files.iter().enumerate() {
        let path = dir.join(name);
        std::fs::create_dir_all(path.parent().expect("a file in the case folder")).expect("case subfolder");
        std::fs::write(path, if i == which { bytes } else { content }).expect("case file");
    }
}

/// `{in}` the main input file, `{indir}` the case's input folder, `{out}`
/// the output folder.
fn substitute(cmd: &[String], input: &Path, indir: &Path, out: &Path) -> Vec<String> {
    cmd.iter()
        .map(|a| {
            a.replace("{indir}", &indir.to_string_lossy()).replace("{in}", &input.to_string_lossy()).replace("{out}", &out.to_string_lossy())
        })
        .collect()
}

/// Runs the intact seed once per command: its peak RSS is the base of the
/// bound; it must itself succeed.
fn baseline(c: &Campaign, seed: &Seed, work: &Path) -> Vec<u64> {
    seed.commands
        .iter()
        .enumerate()
        .map(|(k, cmd)| {
            let dir = work.join(format!("base_{}_{k}", format_hash(&seed.format)));
            lay_out(seed, &dir.join("in"), usize::MAX, &[]);
            std::fs::create_dir_all(dir.join("out")).expect("out folder");
            let argv = substitute(cmd, &dir.join("in").join(seed.main_file()), &dir.join("in"), &dir.join("out"));
            let o = run_child(&c.bin, &argv, &dir.join("stderr"), c.limit);
            assert_eq!(o.code, Some(0), "intact {} input fails {argv:?}: {}", seed.format, o.stderr);
            std::fs::remove_dir_all(&dir).ok();
            o.max_rss
        })
        .collect()
}

/// Runs `count` mutations of every seed, `threads` children at a time.
pub fn run_campaign(c: &Campaign, seeds: &[Seed], work: &Path) -> BTreeMap<String, Stats> {
    let jobs: Vec<(usize, usize)> = (0..seeds.len()).flat_map(|s| (0..c.count).map(move |i| (s, i))).collect();
    let bases: Vec<Vec<u64>> = seeds.iter().map(|s| baseline(c, s, work)).collect();
    let next = AtomicUsize::new(0);
    let stats: Mutex<BTreeMap<String, Stats>> = Mutex::new(BTreeMap::new());
    std::thread::scope(|scope| {
        for _ in 0..c.threads.max(1) {
            scope.spawn(|| loop {
                let j = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(s, i)) = jobs.get(j) else { break };
                let seed = &seeds[s];
                let mut rng = Rng::new(c.seed ^ format_hash(&seed.format) ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                let which = seed.mutable[rng.below(seed.mutable.len())];
                let (bytes, what) = mutate(&seed.files[which].1, &mut rng);
                let k = i % seed.commands.len();
                let dir = work.join(format!("case_{s}_{i}"));
                lay_out(seed, &dir.join("in"), which, &bytes);
                std::fs::create_dir_all(dir.join("out")).expect("out folder");
                let input = dir.join("in").join(seed.main_file());
                let argv = substitute(&seed.commands[k], &input, &dir.join("in"), &dir.join("out"));
                let o = run_child(&c.bin, &argv, &dir.join("stderr"), c.limit);
                let failed = o.code != Some(0);
                let leftovers: Vec<String> = if failed {
                    std::fs::read_dir(dir.join("out"))
                        .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
                        .unwrap_or_default()
                } else {
                    Vec::new()
                };
                let size: u64 = seed.files.iter().enumerate().map(|(f, (_, b))| if f == which { bytes.len() } else { b.len() } as u64).sum();
                let bound = bases[s][k] + RSS_SLACK_BYTES + RSS_PER_INPUT_BYTE * size;
                let why = verdict(&o, &leftovers, bound);
                {
                    let mut all = stats.lock().expect("stats lock");
                    let st = all.entry(seed.format.clone()).or_default();
                    st.runs += 1;
                    match (o.signal, o.code) {
                        (Some(_), _) if o.timed_out => st.timeouts += 1,
                        (Some(_), _) if o.ceiling_hit => st.ceiling += 1,
                        (Some(_), _) => st.signals += 1,
                        (_, Some(0)) => st.exit0 += 1,
                        (_, Some(1)) => st.exit1 += 1,
                        _ => st.other_exit += 1,
                    }
                    st.worst_wall = st.worst_wall.max(o.wall);
                    st.worst_rss = st.worst_rss.max(o.max_rss);
                    if let Some(why) = &why {
                        let last = o.stderr.lines().last().unwrap_or("").chars().take(160).collect::<String>();
                        st.failures.push(format!(
                            "{} #{i} ({}: {what}) `{}`: {why} [{:.1} s, {} MiB] {last}",
                            seed.format,
                            seed.files[which].0,
                            seed.commands[k].join(" "),
                            o.wall.as_secs_f64(),
                            o.max_rss >> 20
                        ));
                    }
                }
                if let (Some(keep), Some(_)) = (&c.keep_failures, &why) {
                    let dest = keep.join(format!("{}_{i}", seed.format.replace([':', '/'], "_")));
                    std::fs::create_dir_all(&dest).ok();
                    lay_out(seed, &dest, which, &bytes);
                }
                std::fs::remove_dir_all(&dir).ok();
            });
        }
    });
    stats.into_inner().expect("stats")
}

/// The table of a campaign, one row per format.
pub fn table(stats: &BTreeMap<String, Stats>) -> String {
    let mut s = String::from("| format | runs | exit 0 | exit 1 (one error line) | other exit | signal | timeout | RSS ceiling | worst time | worst peak RSS | contract broken |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (f, st) in stats {
        s += &format!(
            "| {f} | {} | {} | {} | {} | {} | {} | {} | {:.2} s | {} MiB | {} |\n",
            st.runs,
            st.exit0,
            st.exit1,
            st.other_exit,
            st.signals,
            st.timeouts,
            st.ceiling,
            st.worst_wall.as_secs_f64(),
            st.worst_rss >> 20,
            st.failures.len()
        );
    }
    s
}
