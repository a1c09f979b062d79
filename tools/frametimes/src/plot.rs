//! The comparison picture: frame time over the flight for every log on one chart, and their
//! distributions as cumulative curves, labelled with file names and units. PNG or SVG by the
//! output's extension; the font is embedded, so no system fonts or programs are needed.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::log::FrameLog;

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

#[derive(Debug, thiserror::Error)]
#[error("{path}: {error}")]
pub struct PlotError {
    pub path: String,
    pub error: String,
}

pub fn plot(logs: &[FrameLog], out: &Path, budget_ms: f64) -> Result<(), PlotError> {
    let err = |e: String| PlotError {
        path: out.display().to_string(),
        error: e,
    };
    REGISTER.call_once(|| {
        // The embedded font is valid; a failure would only leave labels out.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
    let size = (1400, 900);
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    // Draw to a temporary file, then rename: no half-written picture is left behind.
    let tmp = out.with_file_name(format!(
        ".{}.tmp.{}",
        out.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        ext.as_deref().unwrap_or("png")
    ));
    let result = match ext.as_deref() {
        Some("svg") => draw(
            SVGBackend::new(&tmp, size).into_drawing_area(),
            logs,
            budget_ms,
        ),
        Some("png") => draw(
            BitMapBackend::new(&tmp, size).into_drawing_area(),
            logs,
            budget_ms,
        ),
        _ => return Err(err("the plot must end in .png or .svg".into())),
    };
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(err(e));
    }
    std::fs::rename(&tmp, out).map_err(|e| err(e.to_string()))
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    logs: &[FrameLog],
    budget_ms: f64,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (top, bottom) = root.split_vertically(480);
    let max_frames = logs.iter().map(|l| l.frames).max().unwrap_or(1);
    let mut all: Vec<f64> = logs
        .iter()
        .flat_map(|l| l.frame_ms().iter().copied())
        .filter(|x| x.is_finite())
        .collect();
    all.sort_by(f64::total_cmp);
    // Scale to the 99.5th percentile so one hitch does not flatten every curve.
    let y_max = (crate::stats::percentile(&all, 99.5) * 1.1).max(1e-3);
    let x_max = (all.last().copied().unwrap_or(1.0) * 1.02).max(1e-3);

    let mut over_time = ChartBuilder::on(&top)
        .caption("Frame time over the flight", ("sans-serif", 26))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..max_frames as f64, 0f64..y_max)
        .map_err(e)?;
    over_time
        .configure_mesh()
        .x_desc("frame")
        .y_desc("frame time (ms)")
        .label_style(("sans-serif", 16))
        .draw()
        .map_err(e)?;
    for (i, log) in logs.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        over_time
            .draw_series(LineSeries::new(
                log.frame_ms()
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| (k as f64, v.min(y_max))),
                c.stroke_width(2),
            ))
            .map_err(e)?
            .label(log.name())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
    }
    if budget_ms.is_finite() && budget_ms < y_max {
        over_time
            .draw_series(LineSeries::new(
                [(0.0, budget_ms), (max_frames as f64, budget_ms)],
                BLACK.mix(0.4),
            ))
            .map_err(e)?
            .label(format!("budget {budget_ms:.2} ms"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], BLACK.mix(0.4)));
    }
    over_time
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(e)?;

    let mut cdf = ChartBuilder::on(&bottom)
        .caption(
            "Distribution (share of frames at or below a frame time)",
            ("sans-serif", 22),
        )
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..x_max, 0f64..1.0)
        .map_err(e)?;
    cdf.configure_mesh()
        .x_desc("frame time (ms)")
        .y_desc("share of frames")
        .label_style(("sans-serif", 16))
        .draw()
        .map_err(e)?;
    for (i, log) in logs.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        let mut v: Vec<f64> = log
            .frame_ms()
            .iter()
            .copied()
            .filter(|x| x.is_finite())
            .collect();
        v.sort_by(f64::total_cmp);
        let n = v.len() as f64;
        cdf.draw_series(LineSeries::new(
            v.iter().enumerate().map(|(k, &x)| (x, (k + 1) as f64 / n)),
            c.stroke_width(2),
        ))
        .map_err(e)?
        .label(log.name())
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
    }
    cdf.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}
