//! Helpers with one home each: atomic file writes, the deterministic random
//! generator, short hex digests, the allocator set-up, stopping on a signal,
//! one writer per folder.

pub mod alloc;
pub mod digest;
pub mod fs;
pub mod interrupt;
pub mod lock;
pub mod progress;
pub mod rng;
pub mod seed;

/// When this command began its work on its folder: set by `main` at start
/// and again when a folder lock is taken ([`lock::lock`]); what a
/// "reusing" message compares stamps with (a stamp older than this was on
/// disk before; this command's children write newer ones).
pub fn command_started() -> std::time::SystemTime {
    if STARTED_NS.load(std::sync::atomic::Ordering::SeqCst) == 0 {
        mark_command_start();
    }
    std::time::UNIX_EPOCH + std::time::Duration::from_nanos(STARTED_NS.load(std::sync::atomic::Ordering::SeqCst))
}

/// Sets [`command_started`] to now.
pub fn mark_command_start() {
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(1, |d| d.as_nanos() as u64);
    STARTED_NS.store(now.max(1), std::sync::atomic::Ordering::SeqCst);
}

static STARTED_NS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
