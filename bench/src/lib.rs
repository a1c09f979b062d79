//! Benchmarks and their report (filled below).
