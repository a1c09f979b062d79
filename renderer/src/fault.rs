//! Faults the tests inject through the `VKTERRAIN_FAULT` environment variable, to check the
//! paths real faults take: a validation message, a lost device, device memory running out, the
//! tile set cut on disk, and controls that break what a check is meant to catch. Where a fault
//! acts, it acts through a method here, so the frame loop says only when.

use crate::interface::TileRecord;
use crate::terrain::Terrain;
use crate::tile::TileInfo;

/// A fault to inject (see the module header); each says where it acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// `validation`: the first frame binds an index buffer at an offset that is not a multiple
    /// of the index size, which the validation layer reports.
    Validation,
    /// `device-lost-at-N`: frame N fails as if the device were lost.
    DeviceLostAt(u64),
    /// `oom-above-MB`: allocating a tile pool larger than MB megabytes fails as if device
    /// memory ran out.
    OomAbove(u64),
    /// `truncate-at-N`: before frame N the tile set file is cut to half its length, as another
    /// process rewriting it would.
    TruncateAt(u64),
    /// `texture-seam`: every other tile (by tile column plus row) samples its texture moved by
    /// 4 samples, a misregistration that shows at tile borders (the seam test's control).
    TextureSeam,
    /// `texture-no-clamp`: the shader is told every tile has all its mips, so tiles whose fine
    /// mips are not resident sample memory nothing was copied to (the clamp test's control).
    TextureNoClamp,
    /// `mirror-bias`: the CPU mirror the read-back heights are checked against adds one unit
    /// to every stored morph offset (the read-back test's control).
    MirrorBias,
    /// `cull-front`: the tiles' front faces are culled instead of their back faces (the control
    /// of the back-face culling test).
    CullFront,
    /// `no-stitch-across`: no stitches where tiles of two pyramid layers meet (the control of
    /// the pyramid's crack test); stitches within a layer stay.
    NoStitchAcross,
    /// `no-stand-in-balance`: where ancestors stand in for tiles of a pyramid's cut (not
    /// checked yet, or failed), the drawn tiles are not balanced, so tiles two layers apart may
    /// meet unstitched (the control of the failed layer tile's crack test).
    NoStandInBalance,
    /// `unsynchronised`: the first frame rewrites a morphed height between the morph pass and
    /// the draws with no barrier, a hazard only synchronisation validation reports (the
    /// barrier test's control).
    Unsynchronised,
    /// `decode-skip`: a compact set's levels are sent as streams but never decoded, so the
    /// pool holds no positions where their blocks go (the control of the decoded flight's
    /// pixel test).
    DecodeSkip,
    /// `decode-count`: every compact level the GPU decodes is said to hold one vertex more
    /// than it does, which the decoder refuses (the refusal path's test).
    DecodeCount,
    /// `made-skip`: the index arrays made on the CPU are never copied into the pool, so their
    /// draws read whatever their regions held before (the control of the made arrays' pixel
    /// test).
    MadeSkip,
}

impl Fault {
    /// [`Fault::from_env`], read once a process (for what asks every frame).
    pub fn of_process() -> Option<Fault> {
        static FAULT: std::sync::OnceLock<Option<Fault>> = std::sync::OnceLock::new();
        *FAULT.get_or_init(Fault::from_env)
    }

    pub fn from_env() -> Option<Fault> {
        let v = std::env::var("VKTERRAIN_FAULT").ok()?;
        match v.as_str() {
            "validation" => Some(Fault::Validation),
            "texture-seam" => Some(Fault::TextureSeam),
            "texture-no-clamp" => Some(Fault::TextureNoClamp),
            "mirror-bias" => Some(Fault::MirrorBias),
            "unsynchronised" => Some(Fault::Unsynchronised),
            "no-stitch-across" => Some(Fault::NoStitchAcross),
            "cull-front" => Some(Fault::CullFront),
            "no-stand-in-balance" => Some(Fault::NoStandInBalance),
            "decode-skip" => Some(Fault::DecodeSkip),
            "decode-count" => Some(Fault::DecodeCount),
            "made-skip" => Some(Fault::MadeSkip),
            _ => {
                let number = |prefix: &str| v.strip_prefix(prefix).and_then(|n| n.parse().ok());
                number("device-lost-at-")
                    .map(Fault::DeviceLostAt)
                    .or_else(|| number("truncate-at-").map(Fault::TruncateAt))
                    .or_else(|| number("oom-above-").map(|mb: u64| Fault::OomAbove(mb << 20)))
            }
        }
    }

    /// Before frame `frame`'s uploads: `truncate-at-N` cuts the tile set's file to half its
    /// length, as another process rewriting it in place would.
    pub fn cut_file_before(self, frame: u64, terrain: &Terrain) {
        if self == Fault::TruncateAt(frame) {
            // Not under a check reading it (a cut there would fault; see `Terrain::check_through`).
            terrain.with_checks_held(|| {
                let half = terrain.set.file_len() / 2;
                let _ = std::fs::OpenOptions::new()
                    .write(true)
                    .open(terrain.set.path())
                    .and_then(|f| f.set_len(half));
            });
        }
    }

    /// A drawn tile's record as the texture controls spoil it: `texture-seam` moves every other
    /// tile's texture by 4 samples, `texture-no-clamp` claims every mip is resident.
    pub fn spoil_record(self, r: &mut TileRecord, info: &TileInfo) {
        match self {
            Fault::TextureSeam if (info.tx + info.ty) % 2 == 1 => r.texture_shift = 4.0,
            Fault::TextureNoClamp => r.texture_finest = 0.0,
            _ => {}
        }
    }
}
