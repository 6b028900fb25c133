//! @brief Sparse convolution on [`SparseGrid`]s with libtorch: features, learnable
//! layers (submanifold conv, 2x transposed conv, dropout) and the fixed operators of
//! the method (trilinear upsampling X_up, level-0 target flooding).
//!
//! # Features
//!
//! A [`SparseTensor`] is a grid (topology, on the CPU, shared through an `Arc`) and an
//! `[N, C]` feature tensor (any device) whose row `i` belongs to grid voxel `i`. For a
//! level, C = 10 in [`Channel`] order (offset, normal, colour, mask). Colours enter the
//! networks scaled as `s = 2 * (2c - 1)` (range [-2, 2], METHOD.md section 1):
//! [`SparseTensor::from_level`] applies it and [`SparseTensor::to_level`] undoes it
//! (`c = (s / 2 + 1) / 2`, clamped to [0, 1]); nothing else in this module rescales.
//!
//! # Submanifold convolution (gather, matmul; autograd scatters back)
//!
//! Output voxels = input voxels. With the grid's cached kernel map `M` (`[N, k^3]`,
//! missing neighbour = row `N`, see [`crate::learn::grid`]) and the weight `W` stored as
//! `[k^3, C_in, C_out]` (viewed as `[k^3 * C_in, C_out]`):
//!
//! 1. append one zero row to the features, so that row `N` reads zeros;
//! 2. gather the neighbours' features of a block of output rows with `index_select`
//!    into an im2col block `[rows, k^3 * C_in]`;
//! 3. multiply the block by `W` into those output rows; add the bias.
//!
//! Without gradients (`tch::no_grad`, or nothing requires grad) the blocks reuse one
//! im2col buffer and write their products straight into the output
//! (`index_select_out`, `mm_out`), so memory stays at one block (see
//! [`set_cpu_chunk_bytes`]). With gradients the whole im2col is gathered at once and
//! kept by autograd for the weight gradient; autograd differentiates `index_select`
//! (into one scatter-add over all rows) and `mm`, so the input, the weight and the
//! bias all get gradients. (Blocks would make each block's backward scatter into a
//! full-size gradient: quadratic work.)
//!
//! The result equals a dense `conv3d` with zero padding over a grid whose inactive
//! voxels are zero, read at the active voxels (tests below), with
//! `W[o, ci, co] = W_dense[co, ci, dx + r, dy + r, dz + r]`, `o` as in the kernel map.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use glam::{IVec3, Vec3};
use rayon::prelude::*;
use tch::{nn, Device, Kind, Tensor};

use crate::learn::grid::{GridError, KernelMap, SparseGrid};
use crate::level::{Channel, Frame, Level, FEATURE_CHANNELS};

/// Errors of the sparse-convolution layer.
#[derive(Debug, thiserror::Error)]
pub enum SparseError {
    #[error(transparent)]
    Grid(#[from] GridError),
    #[error(transparent)]
    Torch(#[from] tch::TchError),
    #[error("{0}")]
    Invalid(String),
    #[error("device: {0}")]
    Device(String),
}

pub type Result<T, E = SparseError> = std::result::Result<T, E>;

fn invalid<T>(msg: impl Into<String>) -> Result<T> {
    Err(SparseError::Invalid(msg.into()))
}

// ------------------------------------------------------------------ device

/// Chooses the device from `cpu`, `cuda`, `cuda:N` or `auto`; returns it with a
/// sentence that says why (for the log).
pub fn pick_device(spec: &str) -> Result<(Device, String)> {
    let spec = spec.trim().to_ascii_lowercase();
    let cuda = tch::Cuda::is_available();
    let count = if cuda { tch::Cuda::device_count() } else { 0 };
    let why_not = "libtorch reports no usable CUDA device (no GPU or driver on this machine, \
                   or a CPU-only libtorch / libtorch_cuda not linked: build with the `cuda` feature)";
    match spec.as_str() {
        "cpu" => Ok((Device::Cpu, format!("CPU as requested ({} threads)", tch::get_num_threads()))),
        "auto" => {
            if cuda {
                Ok((Device::Cuda(0), format!("CUDA is available ({count} device(s)); using cuda:0")))
            } else {
                Ok((
                    Device::Cpu,
                    format!("chose the CPU ({} threads): {why_not}", tch::get_num_threads()),
                ))
            }
        }
        s if s == "cuda" || s.starts_with("cuda:") => {
            let index: usize = match s.strip_prefix("cuda:") {
                None => 0,
                Some(n) => n.parse().map_err(|_| {
                    SparseError::Device(format!("'{spec}' is not a device (cpu, cuda, cuda:N, auto)"))
                })?,
            };
            if !cuda {
                return Err(SparseError::Device(format!("'{spec}' requested but {why_not}")));
            }
            if index as i64 >= count {
                return Err(SparseError::Device(format!(
                    "'{spec}' requested but only {count} CUDA device(s) exist"
                )));
            }
            Ok((Device::Cuda(index), format!("cuda:{index} as requested")))
        }
        _ => Err(SparseError::Device(format!("'{spec}' is not a device (cpu, cuda, cuda:N, auto)"))),
    }
}

/// Colour in [0, 1] to the networks' scale [-2, 2]: `2 * (2c - 1)`.
pub fn colour_to_network(c: f32) -> f32 {
    2.0 * (2.0 * c - 1.0)
}

/// Inverse of [`colour_to_network`], not clamped.
pub fn colour_from_network(s: f32) -> f32 {
    (s / 2.0 + 1.0) / 2.0
}

/// Whether autograd is recording (false inside `tch::no_grad`).
fn grad_mode_enabled() -> bool {
    // SAFETY: at_grad_set_enabled sets the thread-local grad mode and returns the
    // previous one; it is restored at once.
    unsafe {
        let prev = torch_sys::at_grad_set_enabled(1);
        torch_sys::at_grad_set_enabled(prev);
        prev != 0
    }
}

static CPU_CHUNK_BYTES: AtomicUsize = AtomicUsize::new(128 << 20);
const CUDA_CHUNK_BYTES: usize = 256 << 20;

/// Size of one im2col block on the CPU, bytes (default 128 MiB, and at least 2048
/// rows). Measured on 2 shared cores: the GEMM `[rows, k^3 C] x [k^3 C, C_out]` runs
/// 1.5-2x slower with blocks of 512-2048 rows than with >= 8192 rows, which outweighs
/// keeping the block in cache.
pub fn set_cpu_chunk_bytes(bytes: usize) {
    CPU_CHUNK_BYTES.store(bytes.max(1), Ordering::Relaxed);
}

fn chunk_rows(device: Device, row_elems: i64, kind: Kind) -> i64 {
    let bytes = match device {
        Device::Cpu => CPU_CHUNK_BYTES.load(Ordering::Relaxed),
        _ => CUDA_CHUNK_BYTES,
    };
    let elem = kind.elt_size_in_bytes() as i64;
    ((bytes as i64) / (row_elems * elem).max(1)).max(2048)
}

// ------------------------------------------------------------------ SparseTensor

/// Features on a sparse grid: row `i` of `feats` (`[N, C]`) is voxel `i` of `grid`.
#[derive(Debug)]
pub struct SparseTensor {
    pub grid: Arc<SparseGrid>,
    pub feats: Tensor,
}

impl Clone for SparseTensor {
    /// Shares the grid and the feature storage (a shallow clone).
    fn clone(&self) -> Self {
        SparseTensor { grid: self.grid.clone(), feats: self.feats.shallow_clone() }
    }
}

fn channel_slice(t: &Tensor, ch: Channel) -> Tensor {
    t.narrow(1, ch.start() as i64, ch.width() as i64)
}

/// Concatenates the four channel groups in [`Channel`] order.
fn assemble(offset: &Tensor, normal: &Tensor, colour: &Tensor, mask: &Tensor) -> Tensor {
    let mut parts = [
        (Channel::Offset, offset),
        (Channel::Normal, normal),
        (Channel::Colour, colour),
        (Channel::Mask, mask),
    ];
    parts.sort_by_key(|(c, _)| c.start());
    Tensor::cat(&parts.map(|(_, t)| t), 1)
}

impl SparseTensor {
    /// Pairs a grid with `[grid.len(), C]` features.
    pub fn new(grid: Arc<SparseGrid>, feats: Tensor) -> Result<Self> {
        let size = feats.size();
        if size.len() != 2 || size[0] != grid.len() as i64 {
            return invalid(format!(
                "features of shape {size:?} do not fit a grid of {} voxels ([N, C] expected)",
                grid.len()
            ));
        }
        Ok(SparseTensor { grid, feats })
    }

    /// The same grid with other features.
    pub fn with_feats(&self, feats: Tensor) -> Result<Self> {
        Self::new(self.grid.clone(), feats)
    }

    /// Applies `f` to the features (same grid), e.g. `x.map(|f| f.relu())`.
    pub fn map(&self, f: impl FnOnce(&Tensor) -> Tensor) -> Self {
        SparseTensor { grid: self.grid.clone(), feats: f(&self.feats) }
    }

    pub fn len(&self) -> usize {
        self.grid.len()
    }
    pub fn is_empty(&self) -> bool {
        self.grid.is_empty()
    }
    pub fn channels(&self) -> i64 {
        self.feats.size()[1]
    }
    pub fn device(&self) -> Device {
        self.feats.device()
    }
    /// Moves the features (the grid stays on the CPU; kernel maps are copied to the
    /// device on first use and cached).
    pub fn to_device(&self, device: Device) -> Self {
        SparseTensor { grid: self.grid.clone(), feats: self.feats.to_device(device) }
    }
    /// One channel group of a 10-channel tensor, `[N, width]` (a view).
    pub fn channel(&self, ch: Channel) -> Tensor {
        channel_slice(&self.feats, ch)
    }

    /// A level's voxels as network features: 10 channels in [`Channel`] order,
    /// colours scaled to `2 * (2c - 1)`; rows sorted like the grid.
    pub fn from_level(level: &Level, device: Device) -> Result<Self> {
        let n = level.len();
        if [level.offsets.len(), level.normals.len(), level.colours.len(), level.mask.len()]
            .iter()
            .any(|&l| l != n)
        {
            return invalid(format!("level {} has arrays of different lengths", level.index));
        }
        let (grid, order) = SparseGrid::from_unique_coords(level.resolution, &level.coords)?;
        let flat: Vec<f32> = order
            .par_iter()
            .flat_map_iter(|&i| {
                let mut row = [0f32; FEATURE_CHANNELS];
                let put = |row: &mut [f32; FEATURE_CHANNELS], ch: Channel, v: Vec3| {
                    row[ch.start()..ch.start() + 3].copy_from_slice(&v.to_array());
                };
                put(&mut row, Channel::Offset, level.offsets[i]);
                put(&mut row, Channel::Normal, level.normals[i]);
                put(&mut row, Channel::Colour, level.colours[i].to_array().map(colour_to_network).into());
                row[Channel::Mask.start()] = level.mask[i];
                row
            })
            .collect();
        let feats = Tensor::from_slice(&flat).view([n as i64, FEATURE_CHANNELS as i64]).to_device(device);
        Self::new(Arc::new(grid), feats)
    }

    /// Back to a level (unbatched, 10 channels): colours unscaled and clamped to
    /// [0, 1], everything else as stored.
    pub fn to_level(&self, index: usize, frame: Frame) -> Result<Level> {
        if self.grid.batch_size().is_some() {
            return invalid("to_level needs an unbatched tensor (split the batch first)");
        }
        if self.channels() != FEATURE_CHANNELS as i64 {
            return invalid(format!("to_level needs {FEATURE_CHANNELS} channels, got {}", self.channels()));
        }
        let flat: Vec<f32> = Vec::try_from(
            &self.feats.detach().to_device(Device::Cpu).to_kind(Kind::Float).contiguous().view([-1]),
        )?;
        let rows: Vec<&[f32]> = flat.chunks_exact(FEATURE_CHANNELS).collect();
        let v3 = |r: &[f32], ch: Channel| Vec3::from_slice(&r[ch.start()..ch.start() + 3]);
        Ok(Level {
            index,
            resolution: self.grid.resolution(),
            coords: self.grid.coords(),
            offsets: rows.par_iter().map(|r| v3(r, Channel::Offset)).collect(),
            normals: rows.par_iter().map(|r| v3(r, Channel::Normal)).collect(),
            colours: rows
                .par_iter()
                .map(|r| {
                    Vec3::from_array(v3(r, Channel::Colour).to_array().map(|s| colour_from_network(s).clamp(0.0, 1.0)))
                })
                .collect(),
            mask: rows.par_iter().map(|r| r[Channel::Mask.start()]).collect(),
            frame,
        })
    }

    /// Concatenates unbatched tensors (same resolution and channels) into a batch.
    pub fn batch(items: &[&SparseTensor]) -> Result<Self> {
        let grids: Vec<&SparseGrid> = items.iter().map(|t| &*t.grid).collect();
        let grid = SparseGrid::batch(&grids)?;
        let feats: Vec<&Tensor> = items.iter().map(|t| &t.feats).collect();
        Self::new(Arc::new(grid), Tensor::cat(&feats, 0))
    }

    /// The items of a batched tensor (features are views).
    pub fn split(&self) -> Vec<SparseTensor> {
        self.grid
            .split()
            .into_iter()
            .map(|(g, r)| SparseTensor {
                grid: Arc::new(g),
                feats: self.feats.narrow(0, r.start as i64, r.len() as i64),
            })
            .collect()
    }

    /// Keeps the voxels with `keep[i]`.
    pub fn prune(&self, keep: &[bool]) -> Result<Self> {
        let (grid, rows) = self.grid.prune(keep)?;
        let idx = Tensor::from_slice(&rows).to_device(self.device());
        Self::new(Arc::new(grid), self.feats.index_select(0, &idx))
    }

    /// METHOD.md section 5's prune: keeps the voxels whose mask is > 0 and sets their
    /// mask to exactly 1 (10-channel tensors).
    pub fn prune_by_mask(&self) -> Result<Self> {
        if self.channels() != FEATURE_CHANNELS as i64 {
            return invalid("prune_by_mask needs 10-channel features");
        }
        let mask: Vec<f32> = Vec::try_from(
            &self.channel(Channel::Mask).detach().to_device(Device::Cpu).to_kind(Kind::Float).view([-1]),
        )?;
        let keep: Vec<bool> = mask.iter().map(|&m| m > 0.0).collect();
        let pruned = self.prune(&keep)?;
        let feats = pruned.feats.copy();
        let _ = channel_slice(&feats, Channel::Mask).fill_(1.0);
        pruned.with_feats(feats)
    }

    /// The voxels of batch item `batch` in the box of `size` voxels per axis around
    /// `centre` (see [`SparseGrid::crop`]).
    pub fn crop(&self, centre: IVec3, batch: u32, size: i32) -> Result<Self> {
        let (grid, rows) = self.grid.crop(centre, batch, size);
        let idx = Tensor::from_slice(&rows).to_device(self.device());
        Self::new(Arc::new(grid), self.feats.index_select(0, &idx))
    }

    /// The features of batch item `batch` scattered into a dense `[C, X, Y, Z]` box
    /// starting at voxel `min` (zeros elsewhere; voxels outside the box dropped).
    pub fn dense(&self, min: IVec3, size: IVec3, batch: u32) -> Result<Tensor> {
        if size.cmple(IVec3::ZERO).any() {
            return invalid(format!("empty dense box {size}"));
        }
        let (sy, sz) = (size.y as i64, size.z as i64);
        let mut rows = Vec::new();
        let mut at = Vec::new();
        for i in self.grid.batch_ranges().get(batch as usize).cloned().unwrap_or(0..0) {
            let c = self.grid.coord(i) - min;
            if c.cmpge(IVec3::ZERO).all() && c.cmplt(size).all() {
                rows.push(i as i64);
                at.push((c.x as i64 * sy + c.y as i64) * sz + c.z as i64);
            }
        }
        let dev = self.device();
        let c = self.channels();
        let src = self.feats.index_select(0, &Tensor::from_slice(&rows).to_device(dev));
        let flat = Tensor::zeros([size.x as i64 * sy * sz, c], (self.feats.kind(), dev))
            .index_copy(0, &Tensor::from_slice(&at).to_device(dev), &src);
        Ok(flat.tr().reshape([c, size.x as i64, sy, sz]))
    }
}

// ------------------------------------------------------------------ convolution

/// The gather-matmul core: `feats [N, C]`, `map [N, K]` (missing = N), `w [K*C, C_out]`.
fn gather_conv(feats: &Tensor, map: &Tensor, w: &Tensor, rows_per_chunk: Option<i64>) -> Tensor {
    let (n, c) = (feats.size()[0], feats.size()[1]);
    let k3 = map.size()[1];
    let co = w.size()[1];
    let (kind, dev) = (feats.kind(), feats.device());
    if n == 0 {
        return Tensor::zeros([0, co], (kind, dev));
    }
    if k3 == 1 {
        // 1x1x1: the map is the identity.
        return feats.mm(w);
    }
    let padded = Tensor::cat(&[feats, &Tensor::zeros([1, c], (kind, dev))], 0);
    let rows = rows_per_chunk.unwrap_or_else(|| chunk_rows(dev, k3 * c, kind)).max(1).min(n.max(1));
    let needs_grad = grad_mode_enabled() && (feats.requires_grad() || w.requires_grad());
    if !needs_grad {
        let out = Tensor::empty([n, co], (kind, dev));
        let buf = Tensor::empty([rows * k3, c], (kind, dev));
        let mut s = 0;
        while s < n {
            let m = rows.min(n - s);
            let idx = map.narrow(0, s, m).view([m * k3]);
            let cols = buf.narrow(0, 0, m * k3);
            let _ = padded.index_select_out(&cols, 0, &idx);
            let _ = cols.view([m, k3 * c]).mm_out(&out.narrow(0, s, m), w);
            s += m;
        }
        out
    } else {
        // One gather and one product: autograd turns the gather into a single
        // scatter-add over all rows (blocks would each scatter into a full-size
        // gradient, N^2 / block work in all).
        let idx = map.view([n * k3]);
        padded.index_select(0, &idx).view([n, k3 * c]).mm(w)
    }
}

/// Functional submanifold convolution: `weight [k^3, C_in, C_out]`, optional bias
/// `[C_out]`; output voxels = input voxels. `rows_per_chunk` overrides the im2col block.
pub fn subm_conv3d(
    x: &SparseTensor,
    weight: &Tensor,
    bias: Option<&Tensor>,
    rows_per_chunk: Option<i64>,
) -> Result<SparseTensor> {
    let ws = weight.size();
    let k3 = ws.first().copied().unwrap_or(0).max(0) as usize;
    let k = (k3 as f64).cbrt().round() as usize;
    if ws.len() != 3 || k * k * k != k3 || ws[1] != x.channels() {
        return invalid(format!(
            "weight of shape {ws:?} does not fit {} input channels ([k^3, C_in, C_out])",
            x.channels()
        ));
    }
    let map = x.grid.kernel_map(k)?.tensor(x.device());
    let w = weight.reshape([ws[0] * ws[1], ws[2]]);
    let out = gather_conv(&x.feats, &map, &w, rows_per_chunk);
    x.with_feats(match bias {
        Some(b) => out + b,
        None => out,
    })
}

/// Submanifold sparse 3-D convolution (output grid = input grid), kernel 1, 3 or 5
/// (any odd size up to 7). Variables: `weight [k^3, C_in, C_out]`, `bias [C_out]`,
/// initialised uniform in +-1/sqrt(C_in k^3) (PyTorch's conv default).
#[derive(Debug)]
pub struct SubmConv3d {
    pub weight: Tensor,
    pub bias: Option<Tensor>,
    pub kernel_size: usize,
    pub in_channels: i64,
    pub out_channels: i64,
}

impl SubmConv3d {
    pub fn new(vs: &nn::Path, in_channels: i64, out_channels: i64, kernel_size: usize, bias: bool) -> Result<Self> {
        if kernel_size.is_multiple_of(2) || kernel_size > crate::learn::grid::MAX_KERNEL_SIZE {
            return Err(GridError::KernelSize(kernel_size).into());
        }
        let k3 = kernel_size.pow(3) as i64;
        let bound = 1.0 / ((in_channels * k3) as f64).sqrt();
        let init = nn::Init::Uniform { lo: -bound, up: bound };
        let weight = vs.f_var("weight", &[k3, in_channels, out_channels], init)?;
        let bias = if bias { Some(vs.f_var("bias", &[out_channels], init)?) } else { None };
        Ok(SubmConv3d { weight, bias, kernel_size, in_channels, out_channels })
    }

    pub fn forward(&self, x: &SparseTensor) -> Result<SparseTensor> {
        subm_conv3d(x, &self.weight, self.bias.as_ref(), None)
    }
}

/// Transposed convolution, kernel 2, stride 2: every coarse voxel feeds its 8
/// children in the coarse grid's cached subdivision (`child = 2 * parent + (a,b,c)`,
/// code `a*4 + b*2 + c`). Variables: `weight [C_in, 8, C_out]`, `bias [C_out]`,
/// uniform in +-1/sqrt(C_in). Equals a dense `conv_transpose3d` with
/// `W_dense[ci, co, a, b, c] = weight[ci, a*4+b*2+c, co]`.
#[derive(Debug)]
pub struct ConvTranspose2x {
    pub weight: Tensor,
    pub bias: Option<Tensor>,
    pub in_channels: i64,
    pub out_channels: i64,
}

impl ConvTranspose2x {
    pub fn new(vs: &nn::Path, in_channels: i64, out_channels: i64, bias: bool) -> Result<Self> {
        let bound = 1.0 / (in_channels as f64).sqrt();
        let init = nn::Init::Uniform { lo: -bound, up: bound };
        let weight = vs.f_var("weight", &[in_channels, 8, out_channels], init)?;
        let bias = if bias { Some(vs.f_var("bias", &[out_channels], init)?) } else { None };
        Ok(ConvTranspose2x { weight, bias, in_channels, out_channels })
    }

    /// Output on `x.grid.subdivide()?.fine` (the same `Arc` as [`upsample_trilinear`]).
    pub fn forward(&self, x: &SparseTensor) -> Result<SparseTensor> {
        if x.channels() != self.in_channels {
            return invalid(format!("ConvTranspose2x expects {} channels, got {}", self.in_channels, x.channels()));
        }
        let sub = x.grid.subdivide()?;
        let n = x.len() as i64;
        // [N, C_in] x [C_in, 8 C_out] -> one row per (parent, child code) -> children.
        let per_child = x
            .feats
            .mm(&self.weight.reshape([self.in_channels, 8 * self.out_channels]))
            .view([n * 8, self.out_channels]);
        let out = per_child.index_select(0, &sub.source_tensor(x.device()));
        let out = match &self.bias {
            Some(b) => out + b,
            None => out,
        };
        SparseTensor::new(sub.fine.clone(), out)
    }
}

/// Element-wise dropout of the features (active only when `train`).
#[derive(Debug, Clone, Copy)]
pub struct SparseDropout {
    pub p: f64,
}

impl SparseDropout {
    pub fn new(p: f64) -> Self {
        SparseDropout { p }
    }
    pub fn forward_t(&self, x: &SparseTensor, train: bool) -> SparseTensor {
        if !train || self.p == 0.0 {
            return x.clone();
        }
        x.map(|f| f.dropout(self.p, train))
    }
}

// ------------------------------------------------------------------ fixed operators

/// X_up of METHOD.md section 3: the trilinear guess of the fine grid from a coarse
/// 10-channel tensor, on the coarse grid's subdivision (all 8 children per voxel).
///
/// 1. Each coarse voxel's point in coarse voxel units, `P = coord + 0.5 + offset`;
///    its mask weight `m = clamp((mask + 1) / 2, 0, 1)` (1 for active, 0 for mask -1).
/// 2. For each child centre, the 8 nearest coarse centres (all within the parent's
///    3^3 neighbourhood) with trilinear weights `w` (0.75 / 0.25 per axis); missing
///    voxels weigh 0. Points, normals and colours are averaged with weights `w * m`
///    and divided by `sum(w * m)` (the interpolated mask weight); where that sum is 0
///    the parent's values are used. Normals are not renormalised.
/// 3. The child's offset = interpolated point - child centre, in fine voxel units;
///    child mask = `clamp(1 - 2 * max|offset|, -1, 1)` (1 at the centre, 0 on the
///    voxel's boundary); then the offset is clamped to [-0.5, 0.5].
///
/// Colours are interpolated in whatever scale the input uses (the average is
/// affine-invariant). No gradient is needed, but the ops are differentiable.
pub fn upsample_trilinear(coarse: &SparseTensor) -> Result<SparseTensor> {
    if coarse.channels() != FEATURE_CHANNELS as i64 {
        return invalid(format!("upsample_trilinear needs {FEATURE_CHANNELS} channels"));
    }
    let grid = &coarse.grid;
    let sub = grid.subdivide()?;
    let map = grid.kernel_map(3)?;
    let nf = sub.fine.len();
    // Per child: 8 coarse rows and their trilinear weights.
    let mut idx = vec![0i64; nf * 8];
    let mut wt = vec![0f32; nf * 8];
    idx.par_chunks_mut(8).zip(wt.par_chunks_mut(8)).enumerate().for_each(|(i, (id, w))| {
        let p = sub.parent[i] as usize;
        let code = sub.child[i] as i32;
        let a = IVec3::new(code >> 2, (code >> 1) & 1, code & 1);
        let nb = map.neighbours(p);
        for t in 0..8 {
            let tc = IVec3::new(t >> 2, (t >> 1) & 1, t & 1);
            let d = a - IVec3::ONE + tc;
            id[t as usize] = nb[KernelMap::column_of(3, d)];
            w[t as usize] = d.to_array().iter().map(|&x| if x == 0 { 0.75 } else { 0.25 }).product();
        }
    });
    let (dev, kind) = (coarse.device(), coarse.feats.kind());
    let f = &coarse.feats;
    let nf = nf as i64;
    let centres = grid.coords_tensor().to_device(dev).to_kind(kind) + 0.5;
    let pos = centres + channel_slice(f, Channel::Offset);
    let nrm = channel_slice(f, Channel::Normal);
    let col = channel_slice(f, Channel::Colour);
    let mw = ((channel_slice(f, Channel::Mask) + 1.0) * 0.5).clamp(0.0, 1.0);
    let vals = Tensor::cat(&[&pos, &nrm, &col], 1); // [Nc, 9]
    let weighted = Tensor::cat(&[&vals * &mw, mw.shallow_clone()], 1); // [Nc, 10]
    let padded = Tensor::cat(&[weighted, Tensor::zeros([1, 10], (kind, dev))], 0);
    let idx = Tensor::from_slice(&idx).to_device(dev);
    let wt = Tensor::from_slice(&wt).to_device(dev).to_kind(kind).view([nf, 8, 1]);
    let g = padded.index_select(0, &idx).view([nf, 8, 10]);
    let s = (g * wt).sum_dim_intlist(1, false, kind); // [Nf, 10]
    let den = s.narrow(1, 9, 1);
    let parent = Tensor::from_slice(&sub.parent).to_device(dev);
    let fallback = vals.index_select(0, &parent);
    let interp = (s.narrow(1, 0, 9) / den.clamp_min(1e-12)).where_self(&den.gt(1e-12), &fallback);
    let fine_centres = sub.fine.coords_tensor().to_device(dev).to_kind(kind) + 0.5;
    let offset = interp.narrow(1, 0, 3) * 2.0 - fine_centres;
    let mask = (offset.abs().amax([1], true) * -2.0 + 1.0).clamp(-1.0, 1.0);
    let out = assemble(&offset.clamp(-0.5, 0.5), &interp.narrow(1, 3, 3), &interp.narrow(1, 6, 3), &mask);
    SparseTensor::new(sub.fine.clone(), out)
}

/// Level-0 target flooding (METHOD.md section 4): the dense box over each batch
/// item's active voxels; every channel but the mask is the ground truth blurred into
/// the box by one pass of a normalised 9^3 Gaussian (sigma = 1 voxel; weights sum to
/// 1, applied separably) over the zero-filled box (zero outside it too); inactive
/// voxels get mask -1; active voxels keep their true features (mask included).
pub fn flood_blur(gt: &SparseTensor) -> Result<SparseTensor> {
    tch::no_grad(|| {
        let (bx, index) = gt.grid.dense_box()?;
        let (dev, kind) = (gt.device(), gt.feats.kind());
        let c = gt.channels();
        let taps: Vec<f32> = (-4..=4).map(|i: i32| (-(i * i) as f32 / 2.0).exp()).collect();
        let sum: f32 = taps.iter().sum();
        let g = Tensor::from_slice(&taps).to_device(dev).to_kind(kind) / sum as f64;
        let mut parts = Vec::new();
        for (b, bb) in gt.grid.bounding_boxes().into_iter().enumerate() {
            let Some((lo, hi)) = bb else { continue };
            let size = hi - lo + IVec3::ONE;
            let dense = gt.dense(lo, size, b as u32)?.unsqueeze(1); // [C, 1, X, Y, Z]
            let blurred = dense
                .conv3d(&g.view([1, 1, 9, 1, 1]), None::<Tensor>, [1, 1, 1], [4, 0, 0], [1, 1, 1], 1)
                .conv3d(&g.view([1, 1, 1, 9, 1]), None::<Tensor>, [1, 1, 1], [0, 4, 0], [1, 1, 1], 1)
                .conv3d(&g.view([1, 1, 1, 1, 9]), None::<Tensor>, [1, 1, 1], [0, 0, 4], [1, 1, 1], 1);
            parts.push(blurred.view([c, -1]).tr());
        }
        let mut feats = if parts.is_empty() {
            Tensor::zeros([0, c], (kind, dev))
        } else {
            Tensor::cat(&parts, 0).contiguous()
        };
        if c == FEATURE_CHANNELS as i64 {
            let _ = channel_slice(&feats, Channel::Mask).fill_(-1.0);
        }
        let index = Tensor::from_slice(&index).to_device(dev);
        let _ = feats.index_copy_(0, &index, &gt.feats.detach());
        SparseTensor::new(Arc::new(bx), feats)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::nn::VarStore;

    fn rel_err(a: &Tensor, b: &Tensor) -> f64 {
        let diff = (a - b).abs().max().double_value(&[]);
        let scale = b.abs().max().double_value(&[]).max(1e-20);
        diff / scale
    }

    fn assert_close(what: &str, a: &Tensor, b: &Tensor) {
        assert_eq!(a.size(), b.size(), "{what}: shapes");
        let e = rel_err(a, b);
        assert!(e < 1e-5, "{what}: relative error {e:e}");
    }

    /// Grid of the voxels of a d^3 box at `origin` chosen by `keep`, and their
    /// row-major positions in the box.
    fn box_subset(d: i32, origin: IVec3, keep: impl Fn(usize) -> bool) -> (Arc<SparseGrid>, Tensor) {
        let mut coords = Vec::new();
        let mut pos = Vec::new();
        for i in 0..(d * d * d) as usize {
            if keep(i) {
                let di = d as usize;
                coords.push(origin + IVec3::new((i / (di * di)) as i32, ((i / di) % di) as i32, (i % di) as i32));
                pos.push(i as i64);
            }
        }
        (Arc::new(SparseGrid::from_coords(32, &coords).unwrap()), Tensor::from_slice(&pos))
    }

    fn check_conv_vs_dense(k: usize, d: i32, keep: impl Fn(usize) -> bool, chunk: Option<i64>) {
        tch::manual_seed(k as i64 + 10 * d as i64);
        let (cin, cout) = (3i64, 4i64);
        let (grid, pos) = box_subset(d, IVec3::new(-2, 5, 1), keep);
        let n = grid.len() as i64;
        let dd = d as i64;
        let vs = VarStore::new(Device::Cpu);
        let conv = SubmConv3d::new(&vs.root(), cin, cout, k, true).unwrap();
        let f = Tensor::randn([n, cin], (Kind::Float, Device::Cpu));
        let feats = f.copy().set_requires_grad(true);
        let x = SparseTensor::new(grid.clone(), feats.shallow_clone()).unwrap();
        let y = subm_conv3d(&x, &conv.weight, conv.bias.as_ref(), chunk).unwrap();
        // the no-grad path gives the same values
        let y_ng = tch::no_grad(|| subm_conv3d(&x, &conv.weight, conv.bias.as_ref(), chunk).unwrap());
        assert_close("no_grad forward", &y_ng.feats, &y.feats.detach());

        // dense reference: inactive inputs zero, zero padding
        let dense_in = Tensor::zeros([dd * dd * dd, cin], (Kind::Float, Device::Cpu))
            .index_copy(0, &pos, &f)
            .tr()
            .contiguous()
            .view([1, cin, dd, dd, dd])
            .set_requires_grad(true);
        let k3 = k.pow(3) as i64;
        let ki = k as i64;
        let wd = conv.weight.detach().permute([2, 1, 0]).contiguous().view([cout, cin, ki, ki, ki]).set_requires_grad(true);
        let bd = conv.bias.as_ref().unwrap().detach().copy().set_requires_grad(true);
        let r = ki / 2;
        let yd = dense_in.conv3d(&wd, Some(&bd), [1, 1, 1], [r, r, r], [1, 1, 1], 1);
        let yd_rows = yd.view([cout, dd * dd * dd]).tr().index_select(0, &pos);
        assert_close(&format!("k={k} forward"), &y.feats, &yd_rows);

        let rnd = Tensor::randn([n, cout], (Kind::Float, Device::Cpu));
        (&y.feats * &rnd).sum(Kind::Float).backward();
        (&yd_rows * &rnd).sum(Kind::Float).backward();
        let gin_dense = dense_in.grad().view([cin, dd * dd * dd]).tr().index_select(0, &pos);
        assert_close(&format!("k={k} input grad"), &feats.grad(), &gin_dense);
        let gw_dense = wd.grad().view([cout, cin, k3]).permute([2, 1, 0]);
        assert_close(&format!("k={k} weight grad"), &conv.weight.grad(), &gw_dense);
        assert_close(&format!("k={k} bias grad"), &conv.bias.as_ref().unwrap().grad(), &bd.grad());
    }

    #[test]
    fn subm_conv_equals_dense_conv_on_full_box() {
        for (k, d) in [(1, 5), (3, 6), (5, 7)] {
            check_conv_vs_dense(k, d, |_| true, None);
            check_conv_vs_dense(k, d, |_| true, Some(7)); // many blocks
        }
    }

    #[test]
    fn subm_conv_equals_dense_conv_on_sparse_grid() {
        for (k, d) in [(1, 6), (3, 8), (5, 8)] {
            // a deterministic scatter of about half the voxels
            check_conv_vs_dense(k, d, |i| (i * 2654435761) % 7 < 3, None);
            check_conv_vs_dense(k, d, |i| (i * 40503) % 5 < 2, Some(5));
        }
    }

    #[test]
    fn batched_conv_keeps_items_apart() {
        tch::manual_seed(1);
        let (g, _) = box_subset(4, IVec3::ZERO, |i| i % 3 != 0);
        let a = SparseTensor::new(g.clone(), Tensor::randn([g.len() as i64, 2], (Kind::Float, Device::Cpu))).unwrap();
        let b = SparseTensor::new(g.clone(), Tensor::randn([g.len() as i64, 2], (Kind::Float, Device::Cpu))).unwrap();
        let vs = VarStore::new(Device::Cpu);
        let conv = SubmConv3d::new(&vs.root(), 2, 3, 3, true).unwrap();
        let ab = SparseTensor::batch(&[&a, &b]).unwrap();
        let y = conv.forward(&ab).unwrap();
        let parts = y.split();
        assert_close("item 0", &parts[0].feats, &conv.forward(&a).unwrap().feats);
        assert_close("item 1", &parts[1].feats, &conv.forward(&b).unwrap().feats);
    }

    #[test]
    fn conv_transpose_equals_dense_conv_transpose() {
        tch::manual_seed(3);
        let (cin, cout, d) = (3i64, 2i64, 4i64);
        let (grid, pos) = box_subset(d as i32, IVec3::new(1, 0, 2), |i| (i * 7919) % 3 != 1);
        let n = grid.len() as i64;
        let vs = VarStore::new(Device::Cpu);
        let ct = ConvTranspose2x::new(&vs.root(), cin, cout, true).unwrap();
        let f = Tensor::randn([n, cin], (Kind::Float, Device::Cpu));
        let feats = f.copy().set_requires_grad(true);
        let x = SparseTensor::new(grid.clone(), feats.shallow_clone()).unwrap();
        let y = ct.forward(&x).unwrap();
        assert_eq!(y.len(), 8 * grid.len());
        let dense_in = Tensor::zeros([d * d * d, cin], (Kind::Float, Device::Cpu))
            .index_copy(0, &pos, &f)
            .tr()
            .contiguous()
            .view([1, cin, d, d, d])
            .set_requires_grad(true);
        let wd = ct.weight.detach().permute([0, 2, 1]).contiguous().view([cin, cout, 2, 2, 2]).set_requires_grad(true);
        let bd = ct.bias.as_ref().unwrap().detach().copy().set_requires_grad(true);
        let yd = dense_in.conv_transpose3d(&wd, Some(&bd), [2, 2, 2], [0, 0, 0], [0, 0, 0], 1, [1, 1, 1]);
        // fine voxel -> row in the dense [2d]^3 output (grid origin at (1,0,2) -> fine (2,0,4))
        let origin = IVec3::new(2, 0, 4);
        let fpos: Vec<i64> = y
            .grid
            .coords()
            .iter()
            .map(|&c| {
                let c = c - origin;
                ((c.x as i64 * 2 * d) + c.y as i64) * 2 * d + c.z as i64
            })
            .collect();
        let fpos = Tensor::from_slice(&fpos);
        let yd_rows = yd.view([cout, 8 * d * d * d]).tr().index_select(0, &fpos);
        assert_close("transpose forward", &y.feats, &yd_rows);
        let rnd = Tensor::randn([8 * n, cout], (Kind::Float, Device::Cpu));
        (&y.feats * &rnd).sum(Kind::Float).backward();
        (&yd_rows * &rnd).sum(Kind::Float).backward();
        let gin = dense_in.grad().view([cin, d * d * d]).tr().index_select(0, &pos);
        assert_close("transpose input grad", &feats.grad(), &gin);
        let gw = wd.grad().view([cin, cout, 8]).permute([0, 2, 1]);
        assert_close("transpose weight grad", &ct.weight.grad(), &gw);
        assert_close("transpose bias grad", &ct.bias.as_ref().unwrap().grad(), &bd.grad());
        // the output grid is the shared subdivision
        assert!(Arc::ptr_eq(&y.grid, &grid.subdivide().unwrap().fine));
    }

    fn plane_level(res: u32, n: Vec3, d: f32, half: i32) -> Level {
        // Voxels whose centre is within 0.5 voxel (L-inf sense along z) of the plane
        // n.p = d (voxel units); points = centre projected onto the plane along z.
        let mut level = Level { resolution: res, ..Default::default() };
        for x in 0..half {
            for y in 0..half {
                let cx = x as f32 + 0.5;
                let cy = y as f32 + 0.5;
                let pz = (d - n.x * cx - n.y * cy) / n.z;
                let z = pz.floor() as i32;
                level.coords.push(IVec3::new(x, y, z));
                level.offsets.push(Vec3::new(0.0, 0.0, pz - (z as f32 + 0.5)));
                level.normals.push(n);
                level.colours.push(Vec3::new(0.25, 0.5, 1.0));
                level.mask.push(1.0);
            }
        }
        level
    }

    #[test]
    fn level_round_trip_and_colour_scaling() {
        let level = plane_level(16, Vec3::new(0.0, 0.0, 1.0), 4.3, 3);
        let t = SparseTensor::from_level(&level, Device::Cpu).unwrap();
        assert_eq!(t.channels(), 10);
        let col = t.channel(Channel::Colour);
        assert!((col.double_value(&[0, 0]) - (-1.0)).abs() < 1e-6); // 2(2*0.25-1)
        assert!((col.double_value(&[0, 2]) - 2.0).abs() < 1e-6);
        let back = t.to_level(level.index, level.frame).unwrap();
        assert_eq!(back.coords, level.coords);
        for i in 0..level.len() {
            assert!((back.colours[i] - level.colours[i]).abs().max_element() < 1e-6);
            assert!((back.offsets[i] - level.offsets[i]).abs().max_element() < 1e-7);
        }
        // mask prune keeps mask > 0 and sets it to 1
        let m = t.feats.copy();
        let _ = m.narrow(0, 0, 2).narrow(1, Channel::Mask.start() as i64, 1).fill_(-0.5);
        let _ = m.narrow(0, 2, 1).narrow(1, Channel::Mask.start() as i64, 1).fill_(0.3);
        let p = t.with_feats(m).unwrap().prune_by_mask().unwrap();
        assert_eq!(p.len(), level.len() - 2);
        assert_eq!(p.channel(Channel::Mask).min().double_value(&[]), 1.0);
    }

    #[test]
    fn upsample_reproduces_a_plane() {
        // A tilted plane: every interpolated point is a convex combination of coarse
        // points on the plane, so it lies on the plane.
        let n = Vec3::new(0.2, -0.3, 1.0).normalize();
        let d = 4.1;
        let level = plane_level(16, n, d, 8);
        let coarse = SparseTensor::from_level(&level, Device::Cpu).unwrap();
        let fine = upsample_trilinear(&coarse).unwrap();
        assert_eq!(fine.len(), 8 * coarse.len());
        let out = fine.to_level(1, Frame::default()).unwrap();
        let mut positive = 0;
        let mut columns = std::collections::HashMap::new();
        for i in 0..out.len() {
            let c = out.coords[i];
            let p = (c.as_vec3() + Vec3::splat(0.5) + out.offsets[i]) / 2.0; // coarse units
            assert!((out.normals[i] - n).length() < 1e-5);
            assert!((out.colours[i] - Vec3::new(0.25, 0.5, 1.0)).length() < 1e-5);
            let max_off = out.offsets[i].abs().max_element();
            assert!(max_off <= 0.5 + 1e-6);
            if out.mask[i] > 0.0 {
                positive += 1;
                assert!((n.dot(p) - d).abs() < 1e-4, "child {c} point {p} off the plane");
                assert!((out.mask[i] - (1.0 - 2.0 * max_off)).abs() < 1e-5);
                *columns.entry((c.x, c.y)).or_insert(0) += 1;
            } else {
                assert!(out.mask[i] >= -1.0);
            }
        }
        // interior columns (all trilinear neighbours present) mostly hit the plane
        assert!(positive >= 100, "{positive} children with mask > 0");
        assert!(columns.values().all(|&v| v <= 2));
        // a flat, axis-aligned plane at z = 4.3 coarse = 8.6 fine units
        let flat = plane_level(16, Vec3::Z, 4.3, 4);
        let up = upsample_trilinear(&SparseTensor::from_level(&flat, Device::Cpu).unwrap()).unwrap();
        let l = up.to_level(1, Frame::default()).unwrap();
        assert_eq!(l.len(), 8 * 16);
        for i in 0..l.len() {
            let c = l.coords[i];
            let o = l.offsets[i];
            let interior = (1..7).contains(&c.x) && (1..7).contains(&c.y);
            if c.z == 8 {
                assert!((c.z as f32 + 0.5 + o.z - 8.6).abs() < 1e-5, "{c} {o}");
                if interior {
                    // the plane reproduced exactly, centred in x and y
                    assert!(o.x.abs() < 1e-5 && o.y.abs() < 1e-5, "{c} {o}");
                    assert!((l.mask[i] - 0.8).abs() < 1e-5, "{c} {}", l.mask[i]);
                } else {
                    // a missing neighbour: the point is pulled to the parent's, on the
                    // child's face (|offset| = 0.5), so mask 0
                    assert!((o.x.abs().max(o.y.abs()) - 0.5).abs() < 1e-5, "{c} {o}");
                    assert!(l.mask[i].abs() < 1e-5);
                }
            } else {
                assert_eq!(c.z, 9);
                assert!((o.z + 0.5).abs() < 1e-6); // -0.9 clamped
                assert!((l.mask[i] + 0.8).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn flood_blur_keeps_active_values_and_blurs_into_the_box() {
        tch::manual_seed(5);
        let coords = [IVec3::new(0, 0, 0), IVec3::new(3, 1, 2), IVec3::new(1, 4, 0)];
        let grid = Arc::new(SparseGrid::from_coords(16, &coords).unwrap());
        let feats = Tensor::randn([3, 10], (Kind::Float, Device::Cpu));
        let _ = feats.narrow(1, Channel::Mask.start() as i64, 1).fill_(1.0);
        let gt = SparseTensor::new(grid.clone(), feats.shallow_clone()).unwrap();
        let fl = flood_blur(&gt).unwrap();
        assert_eq!(fl.len(), 4 * 5 * 3);
        let rows = fl.grid.lookup(&grid);
        for (i, &r) in rows.iter().enumerate() {
            assert_close("active row", &fl.feats.get(r), &feats.get(i as i64));
        }
        let mask = fl.channel(Channel::Mask);
        assert_eq!(mask.sum(Kind::Float).double_value(&[]), 3.0 - 57.0);
        // one inactive voxel against a direct Gaussian sum
        let q = IVec3::new(2, 2, 1);
        let r = fl.grid.find(q, 0).unwrap() as i64;
        let g1 = |i: i32| (-(i * i) as f64 / 2.0).exp();
        let s1: f64 = (-4..=4).map(g1).sum();
        let mut want = [0f64; 9];
        for i in 0..grid.len() {
            let dd = grid.coord(i) - q;
            if dd.abs().max_element() <= 4 {
                let w = g1(dd.x) * g1(dd.y) * g1(dd.z) / (s1 * s1 * s1);
                for (ch, wv) in want.iter_mut().enumerate() {
                    *wv += w * feats.double_value(&[i as i64, ch as i64]);
                }
            }
        }
        for (ch, w) in want.iter().enumerate() {
            let got = fl.feats.double_value(&[r, ch as i64]);
            assert!((got - w).abs() < 1e-6, "channel {ch}: {got} vs {w}");
        }
    }

    #[test]
    fn devices() {
        let (d, why) = pick_device("auto").unwrap();
        if !tch::Cuda::is_available() {
            assert_eq!(d, Device::Cpu);
            assert!(why.contains("CPU"), "{why}");
            assert!(pick_device("cuda").is_err());
        }
        assert_eq!(pick_device("cpu").unwrap().0, Device::Cpu);
        assert!(pick_device("tpu").is_err());
    }
}
