//! Process set-up for large tensors.

/// Tunes glibc's allocator for large tensors: by default it returns every
/// large block to the OS (mmap / trim), so each big im2col buffer of the sparse
/// convolution is page-faulted in again (measured: docs/design.md, and docs/performance.md:
/// `conv_bench --no-tune`). Call once at start-up.
pub fn tune_allocator() {
    // SAFETY: mallopt only changes allocator thresholds.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 30);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}
