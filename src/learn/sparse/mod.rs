//! @brief Sparse convolution on [`SparseGrid`]s with libtorch: features, learnable
//! layers (submanifold conv, 2x transposed conv, dropout) and the fixed operators of
//! the method (trilinear upsampling X_up, level-0 target flooding).
//!
//! # Features
//!
//! A [`SparseTensor`] is a grid (topology, on the CPU, shared through an `Arc`) and an
//! `[N, C]` feature tensor (any device) whose row `i` belongs to grid voxel `i`. For a
//! level, C = 10 in [`Channel`] order (offset, normal, colour, mask). Colours enter the
//! networks scaled as `s = 2 * (2c - 1)` (range [-2, 2], docs/method.md section 1):
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

mod conv;
mod device;
mod ops;
mod tensor;

pub use conv::*;
pub use device::*;
pub use ops::*;
pub use tensor::*;

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

crate::stage_error!(SparseError);

pub type Result<T, E = SparseError> = std::result::Result<T, E>;

pub(super) fn invalid<T>(msg: impl Into<String>) -> Result<T> {
    Err(SparseError::Invalid(msg.into()))
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

    /// bf16 GEMMs: f32 in and out, values within bf16's rounding of the f32
    /// result, gradients on the f32 weights, and the setting confined to its
    /// scope and thread.
    #[test]
    fn bf16_compute_is_close_and_trains_f32_weights() {
        tch::manual_seed(3);
        let (grid, _) = box_subset(6, IVec3::ZERO, |i| i % 3 != 0);
        let vs = VarStore::new(Device::Cpu);
        let conv = SubmConv3d::new(&vs.root(), 16, 16, 3, true).unwrap();
        let x = SparseTensor::new(grid.clone(), Tensor::randn([grid.len() as i64, 16], (Kind::Float, Device::Cpu))).unwrap();
        let exact = conv.forward(&x).unwrap().feats;
        assert!(!bf16_compute());
        let mixed = {
            let _scope = bf16_compute_scope(true);
            assert!(bf16_compute());
            assert!(!std::thread::spawn(bf16_compute).join().unwrap(), "another thread stays f32");
            let y = conv.forward(&x).unwrap().feats;
            y.sum(Kind::Float).backward();
            y
        };
        assert!(!bf16_compute(), "the scope restores f32");
        assert_eq!(mixed.kind(), Kind::Float);
        let e = rel_err(&mixed.detach(), &exact.detach());
        assert!(e > 0.0 && e < 2e-2, "bf16 result off by {e:e} (or not bf16 at all)");
        let g = conv.weight.grad();
        assert_eq!(g.kind(), Kind::Float);
        assert!(g.abs().sum(Kind::Float).double_value(&[]) > 0.0, "no gradient reached the f32 weights");
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
