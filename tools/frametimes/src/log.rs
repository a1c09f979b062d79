//! Reading a vkterrain frame log: a CSV with a header row and one row per frame.
//!
//! Only `frame` and `frame_ms` are required; every other column is used when present, so logs
//! of older and newer versions (which add columns) read alike. A partially written last line
//! (an interrupted run) is dropped with a note; so are other malformed rows, counted.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: not a vkterrain frame log ({why})", path.display())]
    NotALog { path: PathBuf, why: String },
}

/// One log: its columns by name, one value per kept frame (NaN where a cell was empty).
#[derive(Clone, Debug)]
pub struct FrameLog {
    pub path: PathBuf,
    pub columns: BTreeMap<String, Vec<f64>>,
    pub frames: usize,
    /// What was odd about the file, for the user (dropped lines).
    pub notes: Vec<String>,
}

impl FrameLog {
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns.get(name).map(Vec::as_slice)
    }

    /// Frame times in milliseconds.
    pub fn frame_ms(&self) -> &[f64] {
        self.column("frame_ms").unwrap_or(&[])
    }

    pub fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.path.display().to_string())
    }
}

/// Logs larger than this are refused (about 3 million frames of vkterrain's columns).
pub const MAX_LOG_BYTES: u64 = 1 << 30;

pub fn read(path: &Path) -> Result<FrameLog, LogError> {
    let io = |error| LogError::Io {
        path: path.to_path_buf(),
        error,
    };
    let not_a_log = |why: String| LogError::NotALog {
        path: path.to_path_buf(),
        why,
    };
    // Only regular files of a sane size: /dev/zero or a FIFO would never end.
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(not_a_log("not a regular file".into()));
    }
    if meta.len() > MAX_LOG_BYTES {
        return Err(not_a_log(format!(
            "{} bytes, more than the {} a log may have",
            meta.len(),
            MAX_LOG_BYTES
        )));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    let text = String::from_utf8_lossy(&bytes);
    parse(path, &text)
}

pub fn parse(path: &Path, text: &str) -> Result<FrameLog, LogError> {
    let not_a_log = |why: &str| LogError::NotALog {
        path: path.to_path_buf(),
        why: why.to_string(),
    };
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .ok_or_else(|| not_a_log("empty file"))?
        .split(',')
        .map(|c| c.trim().to_string())
        .collect();
    for required in ["frame", "frame_ms"] {
        if !header.iter().any(|c| c == required) {
            return Err(not_a_log(&format!("no `{required}` column in the header")));
        }
    }
    let rows: Vec<&str> = lines.filter(|l| !l.trim().is_empty()).collect();
    let ends_cleanly = text.ends_with('\n');
    let mut columns: BTreeMap<String, Vec<f64>> =
        header.iter().map(|c| (c.clone(), Vec::new())).collect();
    let mut notes = Vec::new();
    let mut dropped = 0usize;
    let frame_ms_at = header.iter().position(|c| c == "frame_ms").unwrap_or(0);
    for (i, row) in rows.iter().enumerate() {
        let cells: Vec<&str> = row.split(',').collect();
        let values: Option<Vec<f64>> = cells
            .iter()
            .map(|c| {
                let c = c.trim();
                if c.is_empty() {
                    Some(f64::NAN)
                } else {
                    c.parse::<f64>().ok()
                }
            })
            .collect();
        let complete = cells.len() == header.len()
            && values
                .as_ref()
                .is_some_and(|v| v[frame_ms_at].is_finite() && v[frame_ms_at] >= 0.0)
            && (i + 1 < rows.len() || ends_cleanly);
        match values {
            Some(v) if complete => {
                for (name, value) in header.iter().zip(v) {
                    if let Some(col) = columns.get_mut(name) {
                        col.push(value);
                    }
                }
            }
            _ if i + 1 == rows.len() => notes.push(format!(
                "last line {} is incomplete (interrupted run?): ignored",
                i + 2
            )),
            _ => dropped += 1,
        }
    }
    if dropped > 0 {
        notes.push(format!("{dropped} malformed lines ignored"));
    }
    let frames = columns.get("frame_ms").map_or(0, Vec::len);
    if frames == 0 {
        return Err(not_a_log("no complete frame rows"));
    }
    Ok(FrameLog {
        path: path.to_path_buf(),
        columns,
        frames,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_known_columns_and_drops_a_torn_last_line() {
        let text = "frame,time_s,frame_ms,triangles\n0,0,10.5,100\n1,0.1,11.5,200\n2,0.2,1";
        let log = parse(Path::new("a.csv"), text).expect("log");
        assert_eq!(log.frames, 2);
        assert_eq!(log.frame_ms(), &[10.5, 11.5]);
        assert_eq!(log.column("triangles"), Some(&[100.0, 200.0][..]));
        assert!(log.notes[0].contains("incomplete"), "{:?}", log.notes);
    }

    #[test]
    fn a_cut_number_on_the_last_line_counts_as_torn_without_a_final_newline() {
        let log = parse(Path::new("a.csv"), "frame,frame_ms\n0,10\n1,1").expect("log");
        assert_eq!(log.frames, 1);
        let log = parse(Path::new("a.csv"), "frame,frame_ms\n0,10\n1,12\n").expect("log");
        assert_eq!(log.frames, 2);
        assert!(log.notes.is_empty());
    }

    #[test]
    fn other_files_are_refused_clearly() {
        let e = parse(Path::new("x.csv"), "a,b\n1,2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.csv") && e.contains("not a vkterrain frame log"),
            "{e}"
        );
        assert!(parse(Path::new("x.csv"), "").is_err());
        assert!(parse(Path::new("x.csv"), "frame,frame_ms\n")
            .unwrap_err()
            .to_string()
            .contains("no complete"));
    }
}
