//! The integration tests: real files, the real binary, the library as an
//! integrator calls it. One test binary for all of them (each file below is
//! a module), so the library, libtorch and the C++ are linked once, not once
//! per file. `make test` runs the quick ones; the slow ones (`#[ignore]`d,
//! with the reason) run in `make test-slow`, which CI runs too.

#[path = "common/mod.rs"]
mod common;
#[path = "common/hostile.rs"]
mod hostile_harness;

mod commands;
mod docs;
mod encode_real;
mod foundation;
mod hostile;
mod inputs;
mod ladder;
mod mesh_out;
mod pipeline;
mod robustness;
mod studio;
