//! Shared parts of the benchmarks: residency policies replayed on traces.

pub mod residency;
