//! Submanifold convolution (gather, matmul) and the learnable layers.

use super::*;

thread_local! {
    static BF16_COMPUTE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// The seed of this thread's dropout masks and the masks drawn so far,
    /// where a training step set one ([`dropout_stream_scope`]).
    static DROPOUT_STREAM: std::cell::Cell<Option<(u64, u64)>> = const { std::cell::Cell::new(None) };
}

/// Makes [`SparseDropout`] on this thread draw its masks from `seed` (the
/// k-th mask from `seed` and k: [`crate::learn::noise::keep_mask`]) until
/// the returned guard drops, instead of from libtorch's global generator,
/// which two threads would draw from in either order.
pub fn dropout_stream_scope(seed: u64) -> DropoutStreamScope {
    let previous = DROPOUT_STREAM.with(|c| c.replace(Some((seed, 0))));
    DropoutStreamScope { previous }
}

/// Restores the previous [`dropout_stream_scope`] when dropped.
pub struct DropoutStreamScope {
    previous: Option<(u64, u64)>,
}

impl Drop for DropoutStreamScope {
    fn drop(&mut self) {
        DROPOUT_STREAM.with(|c| c.set(self.previous));
    }
}

/// Whether submanifold convolutions on this thread multiply in bf16.
pub fn bf16_compute() -> bool {
    BF16_COMPUTE.with(|c| c.get())
}

/// Makes submanifold convolutions on this thread multiply in bf16 (f32
/// features and weights cast for the GEMM, the result cast back) until the
/// returned guard drops. Per thread: libtorch runs an op on its caller's
/// thread, and parallel tests must not see each other's setting.
pub fn bf16_compute_scope(on: bool) -> Bf16Scope {
    let previous = BF16_COMPUTE.with(|c| c.replace(on));
    Bf16Scope { previous }
}

/// Whether `device` multiplies bf16 in hardware: any CUDA device, or a CPU
/// with AVX512-BF16 or AMX-BF16 that oneDNN (libtorch's bf16 GEMM) may use.
/// Elsewhere libtorch emulates bf16, and a GEMM runs at about 2 GFLOP/s
/// against 35-55 in f32 (measured on a 2-core AVX2 EPYC: a 64-channel
/// level-0 training step 0.87 s in bf16, 0.078 s in f32), so mixed precision
/// there would make training ten times slower, not faster.
/// `ONEDNN_MAX_CPU_ISA` capped below AVX512_CORE_BF16 (`AVX2`, as when an
/// AVX-512 machine stands in for an ordinary one) counts as no bf16.
pub fn bf16_is_native(device: tch::Device) -> bool {
    if device.is_cuda() {
        return true;
    }
    cpu_has_bf16() && !onednn_capped_below_bf16()
}

fn cpu_has_bf16() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        // Every CPU with AMX-BF16 also has AVX512-BF16.
        std::arch::is_x86_feature_detected!("avx512bf16")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether `ONEDNN_MAX_CPU_ISA` names an instruction set without bf16
/// products (oneDNN's names: SSE41, AVX, AVX2, AVX2_VNNI, AVX512_CORE,
/// AVX512_CORE_VNNI below; AVX512_CORE_BF16 and later, ALL, DEFAULT not).
fn onednn_capped_below_bf16() -> bool {
    let Ok(isa) = std::env::var("ONEDNN_MAX_CPU_ISA").or_else(|_| std::env::var("DNNL_MAX_CPU_ISA")) else {
        return false;
    };
    let isa = isa.trim().to_ascii_uppercase();
    ["SSE41", "AVX", "AVX2", "AVX2_VNNI", "AVX2_VNNI_2", "AVX512_CORE", "AVX512_CORE_VNNI"].contains(&isa.as_str())
}

/// How the networks multiply here, in one line for the log: the CPU (or
/// the CUDA device), its widest vector instructions, and whether the
/// convolutions run in bf16 (`want_bf16`, the profile's `train.bf16`, and
/// the hardware has it) or f32.
pub fn compute_path(device: tch::Device, want_bf16: bool) -> String {
    let bf16 = want_bf16 && bf16_is_native(device);
    let products = if bf16 { "bf16 products (f32 weights)" } else { "f32" };
    if let tch::Device::Cuda(i) = device {
        return format!("compute: CUDA device {i}: {products}");
    }
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| t.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split_once(':')).map(|(_, m)| m.trim().to_string()))
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let isa = cpu_isa();
    let capped = if cpu_has_bf16() && onednn_capped_below_bf16() { ", ONEDNN_MAX_CPU_ISA below bf16" } else { "" };
    let why = match (want_bf16, bf16) {
        (true, false) => " (train.bf16 is on, but without bf16 in hardware f32 is about 10x faster than emulated bf16)",
        (false, _) => " (train.bf16 is off)",
        _ => "",
    };
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    format!("compute: {model} ({cores} cores), {isa}{capped}: {products}{why}")
}

/// The widest x86 vector instructions the CPU offers, as a user names them.
fn cpu_isa() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512bf16") {
            "AVX-512 with BF16"
        } else if std::arch::is_x86_feature_detected!("avx512f") {
            "AVX-512 without BF16"
        } else if std::arch::is_x86_feature_detected!("avx2") {
            "AVX2"
        } else {
            "no AVX2"
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::env::consts::ARCH
    }
}

/// Restores the previous setting of [`bf16_compute_scope`] when dropped.
pub struct Bf16Scope {
    previous: bool,
}

impl Drop for Bf16Scope {
    fn drop(&mut self) {
        BF16_COMPUTE.with(|c| c.set(self.previous));
    }
}

/// The gather-matmul core: `feats [N, C]`, `map [N, K]` (missing = N), `w [K*C, C_out]`.
pub(super) fn gather_conv(feats: &Tensor, map: &Tensor, w: &Tensor, rows_per_chunk: Option<i64>) -> Tensor {
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
    let out = if bf16_compute() && x.feats.kind() == Kind::Float {
        // Mixed precision: the GEMM in bf16, features and weights kept in
        // f32 (the casts are differentiable: gradients reach the f32 weights).
        gather_conv(&x.feats.to_kind(Kind::BFloat16), &map, &w.to_kind(Kind::BFloat16), rows_per_chunk)
            .to_kind(Kind::Float)
    } else {
        gather_conv(&x.feats, &map, &w, rows_per_chunk)
    };
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
        match DROPOUT_STREAM.with(|c| c.get()) {
            Some((seed, k)) => {
                DROPOUT_STREAM.with(|c| c.set(Some((seed, k + 1))));
                let (rows, cols) = (x.feats.size()[0] as usize, x.feats.size()[1] as usize);
                let mask_seed = crate::util::rng::Rng::new(seed ^ k.wrapping_mul(0x9E37_79B9_7F4A_7C15)).next_u64();
                let mask = crate::learn::noise::keep_mask(rows, cols, self.p, mask_seed, x.device()).to_kind(x.feats.kind());
                x.map(|f| f * mask)
            }
            None => x.map(|f| f.dropout(self.p, train)),
        }
    }
}
