//! [`SparseTensor`]: a grid and its features, to and from a [`Level`].

use super::*;
/// Colour in [0, 1] to the networks' scale [-2, 2]: `2 * (2c - 1)`.
pub fn colour_to_network(c: f32) -> f32 {
    2.0 * (2.0 * c - 1.0)
}

/// Inverse of [`colour_to_network`], not clamped.
pub fn colour_from_network(s: f32) -> f32 {
    (s / 2.0 + 1.0) / 2.0
}

/// The range each channel of a feature row can take, on the networks' scale:
/// offsets within the voxel ([-0.5, 0.5] voxels), unit normals ([-1, 1] per
/// component), colours in [0, 1] ([-2, 2] after [`colour_to_network`]), the
/// mask ([-1, 1]). (low, high) per channel, in storage order.
pub fn feature_ranges() -> ([f32; FEATURE_CHANNELS], [f32; FEATURE_CHANNELS]) {
    let mut lo = [0f32; FEATURE_CHANNELS];
    let mut hi = [0f32; FEATURE_CHANNELS];
    for (ch, (l, h)) in [
        (Channel::Offset, (-0.5, 0.5)),
        (Channel::Normal, (-1.0, 1.0)),
        (Channel::Colour, (colour_to_network(0.0), colour_to_network(1.0))),
        (Channel::Mask, (-1.0, 1.0)),
    ] {
        for k in ch.start()..ch.start() + ch.width() {
            lo[k] = l;
            hi[k] = h;
        }
    }
    (lo, hi)
}

/// `feats` ([N, 10]) clamped per channel to [`feature_ranges`]: what a clean
/// grid can hold, so a sampler never steps towards an offset outside its
/// voxel, a colour brighter than white or a mask beyond +-1.
pub fn clamp_to_feature_ranges(feats: &Tensor) -> Tensor {
    let (lo, hi) = feature_ranges();
    let opts = (feats.kind(), feats.device());
    let lo = Tensor::from_slice(&lo).to_kind(opts.0).to_device(opts.1).unsqueeze(0);
    let hi = Tensor::from_slice(&hi).to_kind(opts.0).to_device(opts.1).unsqueeze(0);
    feats.maximum(&lo).minimum(&hi)
}

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

pub(super) fn channel_slice(t: &Tensor, ch: Channel) -> Tensor {
    t.narrow(1, ch.start() as i64, ch.width() as i64)
}

/// Concatenates the four channel groups in [`Channel`] order.
pub(super) fn assemble(offset: &Tensor, normal: &Tensor, colour: &Tensor, mask: &Tensor) -> Tensor {
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
        if let Err(e) = level.check_shape() {
            return invalid(e.to_string());
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

    /// docs/method.md section 5's prune: keeps the voxels whose mask is > 0 and sets their
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
