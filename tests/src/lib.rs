//! Cross-crate integration tests that run the real binaries on real data; see `tests/`.
