//! Learning: the only code that touches tensors. Sparse voxel grids and their
//! topology ([`grid`]), sparse tensors and convolution ([`sparse`]), the two
//! networks of a level ([`nn`]), the diffusion schedule ([`schedule`]),
//! training ([`train`]) and sampling ([`sample`]). Sampling reads checkpoints
//! through [`checkpoint`]; it does not import training.

pub mod checkpoint;
pub mod grid;
pub mod nn;
pub mod settings;
pub mod sample;
pub mod schedule;
pub mod noise;
pub mod sparse;
pub mod train;

/// Asks MKL, libtorch's CPU matrix library, for its strict reproducible mode
/// (`MKL_CBWR=AUTO,STRICT`) unless the environment names a mode: the same
/// bits whatever the thread count. Without it, on an AVX-512 machine (a Xeon
/// with AVX512-BF16/FP16, 2026-12-05) a level's weights after the same steps
/// differed between 1 and 2 libtorch threads, and so between a run and its
/// resumed or sharded twin; on the AVX2 machines before they did not. MKL
/// reads the setting once, at its first call, so this runs before any
/// network is built (and at the start of every process, `main`); child
/// processes inherit it.
pub fn reproducible_kernels() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("MKL_CBWR").is_none() {
            std::env::set_var("MKL_CBWR", "AUTO,STRICT");
        }
    });
}

/// libtorch's CPU thread count set to 1 until dropped, then restored: around
/// the operations whose result depends on the thread count, so weights do
/// not. A dense convolution (the training target's blur) and a reduction of
/// a whole tensor to one number (the gradients' norm) split their sums by
/// thread and add the parts in another order; on an AVX-512 machine
/// elementwise sin, cos and exp gave other bits at a thread's split too, so
/// a training step (forward, backward, clipping, update) runs on one thread
/// on the CPU (matrix products alone are the same bits on any count, with
/// [`reproducible_kernels`]).
pub(crate) struct OneThread(i32);

impl OneThread {
    pub(crate) fn new() -> Self {
        let before = tch::get_num_threads();
        if before != 1 {
            tch::set_num_threads(1);
        }
        OneThread(before)
    }
}

impl Drop for OneThread {
    fn drop(&mut self) {
        if self.0 != 1 {
            tch::set_num_threads(self.0);
        }
    }
}
