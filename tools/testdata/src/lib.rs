//! Paths of the real data tests and benchmarks use: `../shared/data` beside the repository
//! (see its README) and the bundled sample. A test that cannot find its data fails with a
//! message saying what is missing; it never skips.

use std::path::PathBuf;

/// The shared data folder (`../shared/data` from the repository root).
pub fn shared_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
}

/// A file of the shared data, or why not.
pub fn try_data(rel: &str) -> Result<PathBuf, String> {
    let p = shared_dir().join(rel);
    if p.is_file() {
        Ok(p)
    } else {
        Err(format!(
            "data missing: {} (the shared data folder must sit beside the repository)",
            p.display()
        ))
    }
}

/// A file of the shared data; panics with a clear message when it is missing (for tests).
pub fn data(rel: &str) -> PathBuf {
    try_data(rel).unwrap_or_else(|e| panic!("test {e}"))
}

/// The bundled sample (Puget Sound 1K heights, 160 m spacing, decimetres).
pub fn sample() -> PathBuf {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../sample/ps_height_1k.png"
    ));
    assert!(p.is_file(), "bundled sample missing: {}", p.display());
    p
}

/// The bundled sample's photo texture (1024 x 1024 RGB over the 1025 x 1025 heights).
pub fn sample_texture() -> PathBuf {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../sample/ps_texture_1k.png"
    ));
    assert!(
        p.is_file(),
        "bundled sample texture missing: {}",
        p.display()
    );
    p
}
