//! What the user can tell the reader that a file does not say: how RGB pixels encode heights,
//! the size of a raw file, the spacing, a vertical scale, and a window to keep. Parsers for the
//! command-line spellings (`terrain-rgb`, `0,0,1025x1025`, `1025x1025`) live here too so that
//! `tiletool`, `vkterrain` and the tests agree on them.

use std::fmt;
use std::str::FromStr;

use crate::DemError;

/// How an RGB(A) PNG packs a height into its colour channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// Mapbox Terrain-RGB: h = -10000 + (R*65536 + G*256 + B) * 0.1 metres.
    TerrainRgb,
    /// Mapzen/AWS Terrarium: h = R*256 + G + B/256 - 32768 metres.
    Terrarium,
}

impl Encoding {
    /// Height in metres of one pixel.
    pub fn decode(self, r: u8, g: u8, b: u8) -> f64 {
        let (r, g, b) = (f64::from(r), f64::from(g), f64::from(b));
        match self {
            Encoding::TerrainRgb => -10000.0 + (r * 65536.0 + g * 256.0 + b) * 0.1,
            Encoding::Terrarium => r * 256.0 + g + b / 256.0 - 32768.0,
        }
    }
}

impl FromStr for Encoding {
    type Err = DemError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "terrain-rgb" | "terrainrgb" | "mapbox" => Ok(Encoding::TerrainRgb),
            "terrarium" => Ok(Encoding::Terrarium),
            _ => Err(DemError::BadArgument {
                arg: "--encoding",
                value: s.to_string(),
                problem: "expected terrain-rgb or terrarium".to_string(),
            }),
        }
    }
}

impl fmt::Display for Encoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Encoding::TerrainRgb => "terrain-rgb",
            Encoding::Terrarium => "terrarium",
        })
    }
}

/// A window of the (mosaicked) grid, in samples: columns `x..x+width`, rows `y..y+height`,
/// row 0 being the northern edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub x: usize,
    pub y: usize,
    pub width: usize,
    pub height: usize,
}

impl FromStr for Crop {
    type Err = DemError;

    /// `X,Y,WxH`, e.g. `0,0,1025x1025`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |problem: &str| DemError::BadArgument {
            arg: "--crop",
            value: s.to_string(),
            problem: problem.to_string(),
        };
        let mut parts = s.split(',');
        let (Some(x), Some(y), Some(size), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return Err(bad("expected X,Y,WxH (e.g. 0,0,1025x1025)"));
        };
        let x = x
            .trim()
            .parse()
            .map_err(|_| bad("X is not a whole number"))?;
        let y = y
            .trim()
            .parse()
            .map_err(|_| bad("Y is not a whole number"))?;
        let (width, height) =
            parse_size(size).map_err(|_| bad("expected X,Y,WxH (e.g. 0,0,1025x1025)"))?;
        if width == 0 || height == 0 {
            return Err(bad("the window must be at least 1x1"));
        }
        Ok(Crop {
            x,
            y,
            width,
            height,
        })
    }
}

impl fmt::Display for Crop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{}x{}", self.x, self.y, self.width, self.height)
    }
}

/// Parses a `WxH` size (e.g. `1025x1025`, `X` also, spaces around each side allowed) into
/// whole numbers of the caller's type: `tiletool --size` (`usize`, for [`ReadOptions::size`])
/// and `vkterrain --size` (`u32` pixels) share the spelling. The error is the message a clap
/// value parser shows after the value. Which sizes make sense is the caller's rule:
/// [`ReadOptions`] refuses a zero side when it is used, `vkterrain` its own pixel range.
pub fn parse_size<T: FromStr>(s: &str) -> Result<(T, T), &'static str> {
    const EXPECTED: &str = "expected WxH";
    let (w, h) = s.split_once(['x', 'X']).ok_or(EXPECTED)?;
    Ok((
        w.trim().parse().map_err(|_| EXPECTED)?,
        h.trim().parse().map_err(|_| EXPECTED)?,
    ))
}

/// Everything [`crate::read`] needs besides the files. `Default` means: no encoding, no size,
/// spacing from the file, vertical scale 1, the whole grid.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// How RGB PNGs encode heights (`--encoding terrain-rgb|terrarium`); required for them.
    pub encoding: Option<Encoding>,
    /// `--size WxH`: required for raw `.r16`/`.f32`, refused for every other kind of file.
    pub size: Option<(usize, usize)>,
    /// `--spacing METRES`: sets both spacings, overriding what the file says. Required for
    /// files that carry no georeferencing (grey PNG/JPEG, raw, un-georeferenced TIFF).
    pub spacing: Option<f64>,
    /// `--vertical-scale METRES_PER_UNIT`: every height is multiplied by it (default 1). Meant
    /// for grey PNG/JPEG and `.r16` whose units are not metres, but applied to any file.
    pub vertical_scale: Option<f64>,
    /// A window of the mosaicked grid to keep; voids are filled inside the window only.
    pub crop: Option<Crop>,
}

impl ReadOptions {
    /// Rejects values no file can make sense of, before any file is opened.
    pub(crate) fn validate(&self) -> Result<(), DemError> {
        if let Some(s) = self.spacing {
            if !(s.is_finite() && s > 0.0) {
                return Err(DemError::BadArgument {
                    arg: "--spacing",
                    value: s.to_string(),
                    problem: "must be a positive number of metres".to_string(),
                });
            }
        }
        if let Some(v) = self.vertical_scale {
            if !(v.is_finite() && v > 0.0) {
                return Err(DemError::BadArgument {
                    arg: "--vertical-scale",
                    value: v.to_string(),
                    problem: "must be a positive number of metres per unit".to_string(),
                });
            }
        }
        if let Some((w, h)) = self.size {
            if w == 0 || h == 0 {
                return Err(DemError::BadArgument {
                    arg: "--size",
                    value: format!("{w}x{h}"),
                    problem: "W and H must be at least 1".to_string(),
                });
            }
        }
        if let Some(c) = self.crop {
            if c.width == 0 || c.height == 0 {
                return Err(DemError::BadArgument {
                    arg: "--crop",
                    value: c.to_string(),
                    problem: "the window must be at least 1x1".to_string(),
                });
            }
        }
        Ok(())
    }

    pub(crate) fn vertical_scale(&self) -> f64 {
        self.vertical_scale.unwrap_or(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_crop() {
        let c: Crop = "0,0,1025x1025".parse().unwrap();
        assert_eq!(
            c,
            Crop {
                x: 0,
                y: 0,
                width: 1025,
                height: 1025
            }
        );
        let c: Crop = " 10, 20 ,3X4".parse().unwrap();
        assert_eq!((c.x, c.y, c.width, c.height), (10, 20, 3, 4));
        assert_eq!(c.to_string(), "10,20,3x4");
        for bad in [
            "",
            "1,2",
            "1,2,3",
            "1,2,3x",
            "a,2,3x4",
            "1,2,3x4,5",
            "-1,0,2x2",
            "0,0,0x4",
        ] {
            let e = bad.parse::<Crop>().unwrap_err().to_string();
            assert!(e.starts_with("--crop"), "{bad:?}: {e}");
        }
    }

    #[test]
    fn parses_encoding_and_size() {
        assert_eq!(
            "terrain-rgb".parse::<Encoding>().unwrap(),
            Encoding::TerrainRgb
        );
        assert_eq!(
            "Terrarium".parse::<Encoding>().unwrap(),
            Encoding::Terrarium
        );
        assert!("rgb".parse::<Encoding>().is_err());
        assert_eq!(parse_size::<usize>("1025x513"), Ok((1025, 513)));
        assert_eq!(parse_size::<u32>(" 64 X 48 "), Ok((64, 48)));
        assert_eq!(parse_size::<usize>("1025"), Err("expected WxH"));
        assert_eq!(parse_size::<u32>("-1x5"), Err("expected WxH"));
        // A zero side parses; the options refuse it when they are used.
        let zero = ReadOptions {
            size: Some(parse_size("0x5").unwrap()),
            ..ReadOptions::default()
        };
        assert!(zero.validate().is_err());
    }

    #[test]
    fn decodes_encodings() {
        // Terrain-RGB: 0 m is 100000 units = (1, 134, 160).
        assert!((Encoding::TerrainRgb.decode(1, 134, 160) - 0.0).abs() < 1e-9);
        // Terrarium: 0 m is 32768 = (128, 0, 0); 1.5 m adds 1 and 128/256.
        assert_eq!(Encoding::Terrarium.decode(128, 0, 0), 0.0);
        assert_eq!(Encoding::Terrarium.decode(128, 1, 128), 1.5);
    }
}
