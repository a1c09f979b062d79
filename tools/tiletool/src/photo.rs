//! Reading the photo texture `tiletool build --texture` drapes over the heights: PNG, JPEG
//! or an RGB(A)/grey GeoTIFF, 8 or 16 bits per channel, decoded to RGB bytes.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use tiles::texture::Photo;

/// Largest photo we decode, in pixels (64K x 64K RGB would already be 12 GiB).
const MAX_PIXELS: u64 = 1 << 32;

pub fn read(path: &Path) -> Result<Photo> {
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

fn read_image(path: &Path) -> Result<Photo> {
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
    Ok(Photo {
        width: rgb.width() as usize,
        height: rgb.height() as usize,
        rgb: rgb.into_raw(),
    })
}

fn read_tiff(path: &Path) -> Result<Photo> {
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
    Ok(Photo {
        width: width as usize,
        height: height as usize,
        rgb,
    })
}
