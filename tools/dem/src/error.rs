//! The one error type of the crate. Every variant displays as a single line that starts with
//! the file it is about (as the user spelled it), so `tiletool` can print it as is.

/// Why a DEM could not be read. `file` is the path as given (for a mosaic: its first tile, or
/// the tile at fault).
#[derive(Debug, thiserror::Error)]
pub enum DemError {
    #[error("no input files given")]
    NoInput,

    /// A command-line value that does not parse or makes no sense (`--crop`, `--size`, ...).
    #[error("{arg} {value:?}: {problem}")]
    BadArgument {
        arg: &'static str,
        value: String,
        problem: String,
    },

    #[error("{file}: cannot read: {source}")]
    Io {
        file: String,
        source: std::io::Error,
    },

    #[error(
        "{file}: unknown kind of file: expected .hgt, .tif/.tiff, .png, .jpg/.jpeg, .r16 or .f32"
    )]
    UnknownFormat { file: String },

    #[error("{file}: empty file")]
    Empty { file: String },

    /// The file is damaged or is not what its extension says (truncated, bad header, ...).
    #[error("{file}: {problem}")]
    Malformed { file: String, problem: String },

    /// A valid file of a kind this crate does not read (RGB TIFF, JPEG-in-TIFF, 16-bit RGB PNG...).
    #[error("{file}: unsupported {problem}")]
    Unsupported { file: String, problem: String },

    /// The file lacks something only the user can supply (`--spacing`, `--encoding`, `--size`),
    /// or an option was given that does not fit this kind of file.
    #[error("{file}: {problem}")]
    Option { file: String, problem: String },

    #[error(
        "{file}: wrong --size {width}x{height}: that needs {expected} bytes, the file has {actual}"
    )]
    WrongSize {
        file: String,
        width: usize,
        height: usize,
        expected: u64,
        actual: u64,
    },

    /// A header claims more samples than we accept, or more than the file could possibly hold;
    /// refused before anything of that size is allocated.
    #[error("{file}: header claims {width}x{height} samples, {problem}")]
    TooLarge {
        file: String,
        width: u64,
        height: u64,
        problem: String,
    },

    #[error("{file}: mismatched mosaic: {problem}")]
    Mosaic { file: String, problem: String },

    /// A sample that is neither a height nor the file's nodata value (NaN without a NaN nodata).
    #[error("{file}: {problem} at column {x}, row {y}")]
    BadSample {
        file: String,
        x: usize,
        y: usize,
        problem: String,
    },

    #[error("{file}: no valid samples: every sample{window} is void")]
    NoValidSamples { file: String, window: String },

    #[error("{file}: crop {crop} does not fit inside the {width}x{height} grid")]
    CropOutside {
        file: String,
        crop: crate::Crop,
        width: usize,
        height: usize,
    },
}

/// How a path is named in messages: as the user gave it.
pub(crate) fn label(path: &std::path::Path) -> String {
    path.display().to_string()
}

/// Decoder messages (png, tiff) are meant for humans but may span lines; ours must not.
pub(crate) fn one_line(message: impl std::fmt::Display) -> String {
    message
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}
