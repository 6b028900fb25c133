//! Device choice and the memory blocks of the convolution.

use super::*;

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

/// Whether autograd is recording (false inside `tch::no_grad`).
pub(super) fn grad_mode_enabled() -> bool {
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
/// rows): the GEMM `[rows, k^3 C] x [k^3 C, C_out]` measured slower with small
/// blocks than the cache saves (docs/performance.md; `conv_bench --chunk-bytes`).
pub fn set_cpu_chunk_bytes(bytes: usize) {
    CPU_CHUNK_BYTES.store(bytes.max(1), Ordering::Relaxed);
}

pub(super) fn chunk_rows(device: Device, row_elems: i64, kind: Kind) -> i64 {
    let bytes = match device {
        Device::Cpu => CPU_CHUNK_BYTES.load(Ordering::Relaxed),
        _ => CUDA_CHUNK_BYTES,
    };
    let elem = kind.elt_size_in_bytes() as i64;
    ((bytes as i64) / (row_elems * elem).max(1)).max(2048)
}
