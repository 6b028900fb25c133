//! The fixed operators of the method: trilinear upsampling X_up and the
//! level-0 target flooding.

use super::*;

/// X_up of docs/method.md section 3: the trilinear guess of the fine grid from a coarse
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

/// Level-0 target flooding (docs/method.md section 4.3): the dense box over each batch
/// item's active voxels; every channel but the mask is the ground truth blurred into
/// the box by one pass of a normalised 9^3 Gaussian (sigma = 1 voxel; weights sum to
/// 1, applied separably) over the zero-filled box (zero outside it too); inactive
/// voxels get mask -1; active voxels keep their true features (mask included).
///
/// On the CPU the blur runs on one libtorch thread: the convolution's result
/// differs in its last bits with the thread count, and the level-0 weights
/// trained on this target must not depend on how many threads a process has
/// (or is granted while it trains). The box is at most a few thousand voxels.
pub fn flood_blur(gt: &SparseTensor) -> Result<SparseTensor> {
    let _one_thread = (gt.device() == Device::Cpu).then(crate::learn::OneThread::new);
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
