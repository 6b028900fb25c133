//! Evaluation (docs/method.md section 7): the measures ([`metrics`]), the `eval`
//! command on folders ([`evaluate`]) and the degradation ladder that
//! calibrates every measure ([`ladder`]).

pub mod evaluate;
pub mod ladder;
pub mod metrics;
