//! Training and sampling noise drawn from a seed alone (tensors; the seeds
//! themselves are [`crate::util::seed`]'s).

use crate::util::rng::Rng;

/// Standard normal noise of `rows` x `cols` from SplitMix64 and Box-Muller on
/// the CPU, from `seed` alone: independent of libtorch's global generator, of
/// the threads and of the device, so the same seed gives the same noise
/// wherever it is drawn.
pub fn standard_normal(rows: usize, cols: usize, seed: u64, device: tch::Device) -> tch::Tensor {
    let mut rng = Rng::new(seed);
    let n = rows * cols;
    let mut v = Vec::with_capacity(n + 1);
    while v.len() < n {
        // Box-Muller: two normals from two uniforms in (0, 1].
        let u1 = 1.0 - rng.uniform();
        let u2 = rng.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let a = std::f64::consts::TAU * u2;
        v.push((r * a.cos()) as f32);
        v.push((r * a.sin()) as f32);
    }
    v.truncate(n);
    tch::Tensor::from_slice(&v).view([rows as i64, cols as i64]).to_device(device)
}

/// Dropout's keep mask of `rows` x `cols` from `seed` alone: each value 0
/// with probability `p`, else `1 / (1 - p)` (so the mask keeps the
/// expectation). Drawn here rather than by libtorch's global generator so
/// that the parts of a training step can run on two threads at once and draw
/// the same masks as on one ([`crate::learn::sparse::dropout_stream_scope`]).
pub fn keep_mask(rows: usize, cols: usize, p: f64, seed: u64, device: tch::Device) -> tch::Tensor {
    let mut rng = Rng::new(seed);
    let keep = (1.0 / (1.0 - p)) as f32;
    let v: Vec<f32> = (0..rows * cols).map(|_| if rng.uniform() < p { 0.0 } else { keep }).collect();
    tch::Tensor::from_slice(&v).view([rows as i64, cols as i64]).to_device(device)
}
