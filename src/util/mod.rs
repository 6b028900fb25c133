//! Helpers with one home each: atomic file writes, the deterministic random
//! generator, short hex digests, the allocator set-up.

pub mod alloc;
pub mod digest;
pub mod fs;
pub mod rng;
