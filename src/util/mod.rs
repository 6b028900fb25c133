//! Helpers with one home each: atomic file writes, the deterministic random
//! generator, short hex digests, the allocator set-up, stopping on a signal,
//! one writer per folder.

pub mod alloc;
pub mod digest;
pub mod fs;
pub mod interrupt;
pub mod lock;
pub mod rng;
