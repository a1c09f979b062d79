//! Reading the photo texture `tiletool build --texture` drapes over the heights: PNG, JPEG
//! or an RGB(A)/grey GeoTIFF, 8 or 16 bits per channel, decoded to RGB bytes; and laying it
//! on the height grid, by both files' georeferencing when both have it.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use tiles::texture::{Frame, Photo};

/// Largest photo we decode, in pixels (64K x 64K RGB would already be 12 GiB).
const MAX_PIXELS: u64 = 1 << 32;

/// A decoded picture and where it lies, if its file says (GeoTIFF tags).
pub struct Picture {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
    pub placement: Option<dem::Placement>,
}

/// How a photo was laid on the heights, for `build`'s report.
pub enum Laid {
    /// By both files' georeferencing; the fraction of the heights' area it covers.
    Georeferenced { crs: dem::Crs, coverage: f64 },
    /// Stretched over the height grid edge to edge, and why.
    Spanning(&'static str),
}

impl std::fmt::Display for Laid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Laid::Georeferenced { crs, coverage } if *coverage >= 1.0 => {
                write!(f, "aligned by georeferencing ({crs}), covering the heights")
            }
            Laid::Georeferenced { crs, coverage } => write!(
                f,
                "aligned by georeferencing ({crs}), covering {:.1}% of the heights (grey beyond it)",
                coverage * 100.0
            ),
            Laid::Spanning(why) => write!(f, "taken to span the height grid exactly ({why})"),
        }
    }
}

/// Lays `picture` (read from `path`) on `grid`: by georeferencing when both have it, else
/// spanning the grid. Refuses, naming the file, a photo in another coordinate system or one
/// that does not overlap the heights.
pub fn lay(
    picture: Picture,
    path: &Path,
    grid: &dem::HeightGrid,
    view: &tiles::Grid,
) -> Result<(Photo, Laid)> {
    let name = path.display();
    let Picture {
        width,
        height,
        rgb,
        placement,
    } = picture;
    let (photo_at, heights_at) = match (placement, grid.placement) {
        (Some(p), Some(h)) => (p, h),
        (None, _) => {
            let photo = Photo::spanning(width, height, rgb, view);
            return Ok((photo, Laid::Spanning("the photo has no georeferencing")));
        }
        (Some(_), None) => {
            let photo = Photo::spanning(width, height, rgb, view);
            let why = "the heights have no georeferencing";
            return Ok((photo, Laid::Spanning(why)));
        }
    };
    let dem::Mapping {
        origin: (ox, oy),
        step,
    } = heights_at
        .in_grid_of(&photo_at)
        .map_err(|e| anyhow!("{name}: cannot lay this photo on the heights: {e}"))?;
    // `in_grid_of` maps to pixel centres; the frame wants pixel edges (centre = edge + 0.5).
    let photo = Photo {
        width,
        height,
        rgb,
        frame: Frame {
            origin: (ox + 0.5, oy + 0.5),
            step,
        },
        georeferenced: true,
    };
    let coverage = photo.coverage(view);
    if coverage <= 0.0 {
        bail!(
            "{name}: the photo does not overlap the heights: it spans {}, the heights {}",
            photo_at.extent(width, height),
            heights_at.extent(grid.width, grid.height)
        );
    }
    let crs = heights_at.crs;
    Ok((photo, Laid::Georeferenced { crs, coverage }))
}

pub fn read(path: &Path) -> Result<Picture> {
    let name = path.display();
    let meta = std::fs::metadata(path).with_context(|| format!("{name}"))?;
    if !meta.is_file() {
        bail!("{name}: not a regular file");
    }
    let mut magic = [0u8; 4];
    {
        use std::io::Read;
        let mut f = std::fs::File::open(path).with_context(|| format!("{name}"))?;
        let n = f.read(&mut magic).with_context(|| format!("{name}"))?;
        if n == 0 {
            bail!("{name}: empty file");
        }
    }
    let photo = if matches!(magic, [b'I', b'I', 42 | 43, 0] | [b'M', b'M', 0, 42 | 43]) {
        read_tiff(path)?
    } else {
        read_image(path)?
    };
    if photo.width < 2 || photo.height < 2 {
        bail!(
            "{name}: a {}x{} picture is too small for a texture",
            photo.width,
            photo.height
        );
    }
    Ok(photo)
}

fn read_image(path: &Path) -> Result<Picture> {
    let name = path.display();
    let reader = image::ImageReader::open(path)
        .with_context(|| format!("{name}"))?
        .with_guessed_format()
        .with_context(|| format!("{name}"))?;
    if reader.format().is_none() {
        bail!("{name}: not a PNG, JPEG or TIFF picture");
    }
    let decoded = reader
        .decode()
        .map_err(|e| anyhow!("{name}: cannot decode the texture: {e}"))?;
    let rgb = decoded.to_rgb8();
    Ok(Picture {
        width: rgb.width() as usize,
        height: rgb.height() as usize,
        rgb: rgb.into_raw(),
        placement: None,
    })
}

fn read_tiff(path: &Path) -> Result<Picture> {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::ColorType;
    let name = path.display();
    let file = std::fs::File::open(path).with_context(|| format!("{name}"))?;
    let bad = |e: tiff::TiffError| anyhow!("{name}: cannot decode the texture: {e}");
    let mut decoder = Decoder::new(std::io::BufReader::new(file)).map_err(bad)?;
    let (width, height) = decoder.dimensions().map_err(bad)?;
    if u64::from(width) * u64::from(height) > MAX_PIXELS {
        bail!("{name}: a {width}x{height} texture is larger than this tool decodes");
    }
    let colour = decoder.colortype().map_err(bad)?;
    let channels = match colour {
        ColorType::RGB(8 | 16) => 3,
        ColorType::RGBA(8 | 16) => 4,
        ColorType::Gray(8 | 16) => 1,
        other => bail!("{name}: a {other:?} TIFF is not an RGB or grey picture"),
    };
    let samples: Vec<u8> = match decoder.read_image().map_err(bad)? {
        DecodingResult::U8(v) => v,
        DecodingResult::U16(v) => v.into_iter().map(|s| (s >> 8) as u8).collect(),
        _ => bail!("{name}: texture samples are not 8 or 16-bit integers"),
    };
    let pixels = width as usize * height as usize;
    if samples.len() < pixels * channels {
        bail!("{name}: the texture holds fewer samples than its size says");
    }
    let rgb = samples
        .chunks_exact(channels)
        .take(pixels)
        .flat_map(|p| match channels {
            1 => [p[0]; 3],
            _ => [p[0], p[1], p[2]],
        })
        .collect();
    let placement = dem::read_tiff_placement(path)?;
    Ok(Picture {
        width: width as usize,
        height: height as usize,
        rgb,
        placement,
    })
}
