//! Test fixtures (unit tests, the integration tests and the benchmarks, with
//! the `testing` feature): shapes with known answers.

pub mod shapes;
pub mod synthetic;
pub mod clouds;
