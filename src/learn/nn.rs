//! @brief The two learned networks of a level (docs/method.md section 3): the diffusion
//! model M_l, which predicts the clean grid x0 from a noised grid and its time, and
//! the upsampler U_l, which predicts the fine grid from the coarse one.
//!
//! Both are stacks of sparse convolutions from [`crate::learn::sparse`]; every
//! convolution keeps its input's active set (the upsampler's transposed convolution
//! goes to the coarse grid's subdivision). Each model lives in its own
//! [`nn::VarStore`] (see [`LevelNet`]), so it is saved, loaded and optimised alone.
//!
//! Widths and depths come from [`ModelConfig`]: `level0_*` for level 0, `upper_*` for
//! levels >= 1, `channels` for the diffusion model, `upsampler_channels` for U_l.

use std::path::Path;

use tch::{nn, Device, Kind, Tensor};

use crate::config::ModelConfig;
use crate::learn::schedule::time_embedding_rows;
use crate::error::{Error, Result};
use crate::level::FEATURE_CHANNELS;
use crate::learn::sparse::{upsample_trilinear, ConvTranspose2x, SparseDropout, SparseTensor, SubmConv3d};

/// Width of the time embedding concatenated to each voxel's features.
pub const TIME_CHANNELS: i64 = 6;


/// The shape of a level's diffusion model, read from the configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiffusionShape {
    pub channels: i64,
    /// Convolutions with spatial support: the first (kernel `first_kernel`) and
    /// `layers - 1` of kernel 3.
    pub layers: usize,
    pub first_kernel: usize,
    /// 1x1 convolutions C -> C before the output layer.
    pub head_layers: usize,
}

impl DiffusionShape {
    pub fn for_level(config: &ModelConfig, level: usize) -> Self {
        if level == 0 {
            DiffusionShape {
                channels: config.channels,
                layers: config.level0_layers,
                first_kernel: config.level0_first_kernel,
                head_layers: config.level0_head_layers,
            }
        } else {
            DiffusionShape {
                channels: config.channels,
                layers: config.upper_layers,
                first_kernel: config.upper_first_kernel,
                head_layers: config.upper_head_layers,
            }
        }
    }
}

/// Diffusion model M_l: predicts x0 (10 channels) from x_t and t.
///
/// `[x_t, emb(t)]` (16 ch) -> conv k1 -> dropout -> SiLU -> (layers-1) x [conv 3^3 ->
/// dropout -> SiLU] -> head_layers x [1x1 -> SiLU] -> 1x1 -> 10 channels.
/// No normalisation, no residuals: the receptive field stays small on purpose.
#[derive(Debug)]
pub struct DiffusionNet {
    convs: Vec<SubmConv3d>,
    head: Vec<SubmConv3d>,
    out: SubmConv3d,
    dropout: SparseDropout,
    pub shape: DiffusionShape,
}

impl DiffusionNet {
    pub fn new(p: &nn::Path, shape: DiffusionShape, dropout: f64) -> Result<Self> {
        let c = shape.channels;
        let mut convs = Vec::with_capacity(shape.layers);
        let input = FEATURE_CHANNELS as i64 + TIME_CHANNELS;
        convs.push(SubmConv3d::new(&(p / "conv0"), input, c, shape.first_kernel, true)?);
        for i in 1..shape.layers {
            convs.push(SubmConv3d::new(&(p / format!("conv{i}")), c, c, 3, true)?);
        }
        let head = (0..shape.head_layers)
            .map(|i| SubmConv3d::new(&(p / format!("head{i}")), c, c, 1, true).map_err(Error::from))
            .collect::<Result<Vec<_>>>()?;
        let out = SubmConv3d::new(&(p / "out"), c, FEATURE_CHANNELS as i64, 1, true)?;
        Ok(DiffusionNet { convs, head, out, dropout: SparseDropout::new(dropout), shape })
    }

    /// `t`: the diffusion time of every voxel, `[N]` (or a scalar tensor for all).
    /// Dropout is active only when `train`.
    pub fn forward_t(&self, x: &SparseTensor, t: &Tensor, train: bool) -> Result<SparseTensor> {
        let n = x.len() as i64;
        let t = if t.dim() == 0 { t.expand([n], false) } else { t.shallow_clone() };
        if t.size() != [n] {
            return Err(Error::Invalid(format!("time tensor of shape {:?} for {n} voxels", t.size())));
        }
        let emb = time_embedding_rows(&t.to_device(x.device()).to_kind(x.feats.kind()));
        let mut h = x.with_feats(Tensor::cat(&[&x.feats, &emb], 1))?;
        for conv in &self.convs {
            h = self.dropout.forward_t(&conv.forward(&h)?, train).map(|f| f.silu());
        }
        for conv in &self.head {
            h = conv.forward(&h)?.map(|f| f.silu());
        }
        self.out.forward(&h).map_err(Error::from)
    }

    /// Floating-point operations of one forward pass per voxel: 2 k^3 C_in
    /// C_out for every convolution (the im2col GEMM, absent neighbours
    /// included, as computed), biases and activations left out. A training
    /// step (forward, input and weight gradients) costs about three times this.
    pub fn flops_per_voxel(&self) -> f64 {
        self.convs
            .iter()
            .chain(&self.head)
            .chain(std::iter::once(&self.out))
            .map(|c| 2.0 * c.kernel_size.pow(3) as f64 * c.in_channels as f64 * c.out_channels as f64)
            .sum()
    }

    /// [`Self::forward_t`] with one time for all voxels.
    pub fn forward_at(&self, x: &SparseTensor, t: f64, train: bool) -> Result<SparseTensor> {
        let tt = Tensor::from(t as f32).to_device(x.device());
        self.forward_t(x, &tt, train)
    }
}

/// Upsampler U_l: the coarse grid (10 ch) to its subdivision (10 ch).
///
/// conv 3^3 10->C -> dropout -> ReLU -> transposed conv 2x C->C -> dropout -> ReLU ->
/// 1x1 C->C -> dropout -> ReLU -> 1x1 C->10, plus the residual X_up
/// ([`upsample_trilinear`]). The output's grid is the coarse grid's cached
/// subdivision (the same `Arc` as X_up's).
#[derive(Debug)]
pub struct Upsampler {
    conv_in: SubmConv3d,
    up: ConvTranspose2x,
    mid: SubmConv3d,
    out: SubmConv3d,
    dropout: SparseDropout,
}

impl Upsampler {
    pub fn new(p: &nn::Path, channels: i64, dropout: f64) -> Result<Self> {
        let f = FEATURE_CHANNELS as i64;
        Ok(Upsampler {
            conv_in: SubmConv3d::new(&(p / "conv_in"), f, channels, 3, true)?,
            up: ConvTranspose2x::new(&(p / "up"), channels, channels, true)?,
            mid: SubmConv3d::new(&(p / "mid"), channels, channels, 1, true)?,
            out: SubmConv3d::new(&(p / "out"), channels, f, 1, true)?,
            dropout: SparseDropout::new(dropout),
        })
    }

    pub fn forward_t(&self, coarse: &SparseTensor, train: bool) -> Result<SparseTensor> {
        let x_up = upsample_trilinear(coarse)?;
        let d = |x: SparseTensor| self.dropout.forward_t(&x, train).map(|f| f.relu());
        let h = d(self.conv_in.forward(coarse)?);
        let h = d(self.up.forward(&h)?);
        let h = d(self.mid.forward(&h)?);
        let h = self.out.forward(&h)?;
        debug_assert!(std::sync::Arc::ptr_eq(&h.grid, &x_up.grid));
        x_up.with_feats(&x_up.feats.detach() + &h.feats).map_err(Error::from)
    }
}

/// A network with its own variable store.
pub struct LevelNet<N> {
    pub vs: nn::VarStore,
    pub net: N,
}

impl<N> LevelNet<N> {
    /// Number of learnable scalars.
    pub fn parameters(&self) -> i64 {
        self.vs.trainable_variables().iter().map(|v| v.numel() as i64).sum()
    }

    /// Loads a safetensors checkpoint written by [`Self::save`] (names and shapes must match).
    pub fn load(&mut self, path: &Path) -> Result<()> {
        self.vs.load(path).map_err(|e| Error::file(path, format!("cannot load checkpoint: {e}")))
    }

    /// Saves as safetensors, atomically (temporary file in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::util::fs::write_atomically(path, |tmp| {
            self.vs.save(tmp).map_err(|e| Error::file(path, format!("cannot save checkpoint: {e}")))
        })
    }
}

/// A freshly initialised diffusion model for `level` (initialisation draws from
/// libtorch's global generator: seed it first for reproducible weights).
pub fn new_diffusion(config: &ModelConfig, level: usize, device: Device) -> Result<LevelNet<DiffusionNet>> {
    super::reproducible_kernels();
    let vs = nn::VarStore::new(device);
    let net = DiffusionNet::new(&vs.root(), DiffusionShape::for_level(config, level), config.dropout)?;
    Ok(LevelNet { vs, net })
}

/// A freshly initialised upsampler (levels >= 1).
pub fn new_upsampler(config: &ModelConfig, device: Device) -> Result<LevelNet<Upsampler>> {
    super::reproducible_kernels();
    let vs = nn::VarStore::new(device);
    let net = Upsampler::new(&vs.root(), config.upsampler_channels, config.upsampler_dropout)?;
    Ok(LevelNet { vs, net })
}

/// Mean squared error over all voxels and channels.
pub fn mse(pred: &Tensor, target: &Tensor) -> Tensor {
    (pred - target).square().mean(Kind::Float)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::learn::grid::SparseGrid;
    use glam::IVec3;
    use std::sync::Arc;

    fn cube(n: i32) -> SparseTensor {
        let g = SparseGrid::full_box(16, IVec3::ZERO, IVec3::splat(n)).unwrap();
        let len = g.len() as i64;
        SparseTensor::new(Arc::new(g), Tensor::randn([len, 10], (Kind::Float, Device::Cpu))).unwrap()
    }

    #[test]
    fn shapes_and_parameter_counts() {
        let mut c = Config::load("paper", &[]).unwrap().model;
        tch::manual_seed(0);
        let m0 = new_diffusion(&c, 0, Device::Cpu).unwrap();
        let m1 = new_diffusion(&c, 1, Device::Cpu).unwrap();
        // docs/method.md section 3: ~0.57 M and ~1.2 M parameters.
        let (p0, p1) = (m0.parameters(), m1.parameters());
        assert!((500_000..650_000).contains(&p0), "level 0: {p0}");
        assert!((1_100_000..1_300_000).contains(&p1), "level 1: {p1}");
        c.channels = 8;
        c.upsampler_channels = 4;
        let m = new_diffusion(&c, 1, Device::Cpu).unwrap();
        let x = cube(4);
        let y = m.net.forward_at(&x, 0.2, true).unwrap();
        assert_eq!(y.feats.size(), vec![64, 10]);
        let u = new_upsampler(&c, Device::Cpu).unwrap();
        let f = u.net.forward_t(&x, false).unwrap();
        assert_eq!(f.len(), 8 * 64);
        assert_eq!(f.grid.resolution(), 32);
    }

    #[test]
    fn time_changes_the_output_and_eval_is_deterministic() {
        let mut c = Config::load("cpu", &[]).unwrap().model;
        c.channels = 8;
        tch::manual_seed(1);
        let m = new_diffusion(&c, 0, Device::Cpu).unwrap();
        let x = cube(3);
        let a = m.net.forward_at(&x, 0.1, false).unwrap().feats;
        let b = m.net.forward_at(&x, 0.1, false).unwrap().feats;
        let d = m.net.forward_at(&x, 0.9, false).unwrap().feats;
        assert!(a.equal(&b));
        assert!((&a - &d).abs().max().double_value(&[]) > 1e-4);
    }
}
