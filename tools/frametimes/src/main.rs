//! `frametimes`: summarise and compare vkterrain frame-timing logs.
//!
//! ```text
//! frametimes summary run.csv [--json] [--budget-ms 16.67]
//! frametimes compare before.csv after.csv [more.csv ...] [--json] [--plot cmp.png|cmp.svg]
//!                    [--fail-if-slower PERCENT] [--budget-ms 16.67]
//! ```
//!
//! Exit codes: 0 fine, 1 an error (one line naming the file), 3 `--fail-if-slower` tripped.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};
use frametimes::compare::{compare, Comparison};
use frametimes::log::{read, FrameLog};
use frametimes::stats::Stats;

#[derive(Parser)]
#[command(
    name = "frametimes",
    version,
    about = "Summarise and compare vkterrain frame-timing logs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Figures of one log.
    Summary {
        log: PathBuf,
        #[arg(long)]
        json: bool,
        /// Frame budget for jank and frames over budget, ms.
        #[arg(long, default_value_t = 1000.0 / 60.0)]
        budget_ms: f64,
    },
    /// Logs side by side, ratios to the first, and whether differences are beyond noise.
    Compare {
        #[arg(required = true, num_args = 2..)]
        logs: Vec<PathBuf>,
        #[arg(long)]
        json: bool,
        /// Write a picture of frame time over the flight and the distributions (.png or .svg).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Exit with code 3 when a log's median is slower than the first's by more than PERCENT,
        /// beyond noise (the whole 95% interval of the median ratio above 1 + PERCENT/100).
        #[arg(long)]
        fail_if_slower: Option<f64>,
        #[arg(long, default_value_t = 1000.0 / 60.0)]
        budget_ms: f64,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("frametimes: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn notes(log: &FrameLog) {
    for n in &log.notes {
        eprintln!("frametimes: note: {}: {n}", log.path.display());
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.digits$}"))
}

/// One log's cell: the value as text, and as a number for ratios.
type Cell = (String, Option<f64>);

/// Table rows: label, and each log's cell.
fn rows(stats: &[Stats]) -> Vec<(String, Vec<Cell>)> {
    let num = |f: &dyn Fn(&Stats) -> Option<f64>, digits: usize| -> Vec<Cell> {
        stats.iter().map(|s| (opt(f(s), digits), f(s))).collect()
    };
    let mut out = vec![
        ("frames".into(), num(&|s| Some(s.frames as f64), 0)),
        ("duration (s)".into(), num(&|s| Some(s.duration_s), 2)),
        ("mean (ms)".into(), num(&|s| Some(s.mean_ms), 3)),
        ("median (ms)".into(), num(&|s| Some(s.median_ms), 3)),
        ("p95 (ms)".into(), num(&|s| Some(s.p95_ms), 3)),
        ("p99 (ms)".into(), num(&|s| Some(s.p99_ms), 3)),
        ("max (ms)".into(), num(&|s| Some(s.max_ms), 3)),
        ("std dev (ms)".into(), num(&|s| Some(s.std_dev_ms), 3)),
        ("jank (ms)".into(), num(&|s| Some(s.jank_ms), 1)),
        (
            "frames over budget".into(),
            num(&|s| Some(s.frames_over_budget as f64), 0),
        ),
        ("Mtri/s".into(), num(&|s| s.mtri_per_s, 2)),
        ("upload (MB)".into(), num(&|s| s.upload_mb, 2)),
        ("GPU median (ms)".into(), num(&|s| s.gpu_median_ms, 3)),
    ];
    for stage in frametimes::stats::CPU_STAGES {
        if stats
            .iter()
            .any(|s| s.cpu_stages_ms.iter().any(|(n, _)| n == stage))
        {
            let label = format!("{} (mean ms)", stage.trim_end_matches("_ms"));
            out.push((
                label,
                num(
                    &|s| {
                        s.cpu_stages_ms
                            .iter()
                            .find(|(n, _)| n == stage)
                            .map(|(_, v)| *v)
                    },
                    4,
                ),
            ));
        }
    }
    out
}

fn print_table(stats: &[Stats]) {
    let mut header = vec!["".to_string()];
    header.extend(stats.iter().map(|s| s.file.clone()));
    header.extend(
        stats
            .iter()
            .skip(1)
            .map(|s| format!("{} / {}", short(&s.file), short(&stats[0].file))),
    );
    let table: Vec<Vec<String>> = rows(stats)
        .into_iter()
        .map(|(label, values)| {
            let base = values[0].1;
            let mut line = vec![label];
            line.extend(values.iter().map(|v| v.0.clone()));
            line.extend(values.iter().skip(1).map(|v| match (v.1, base) {
                (Some(x), Some(b)) if b != 0.0 => format!("{:.3}", x / b),
                _ => "-".into(),
            }));
            line
        })
        .collect();
    let widths: Vec<usize> = (0..header.len())
        .map(|c| {
            std::iter::once(&header)
                .chain(&table)
                .map(|r| r[c].chars().count())
                .max()
                .unwrap_or(0)
        })
        .collect();
    for row in std::iter::once(&header).chain(&table) {
        let cells: Vec<String> = row
            .iter()
            .zip(&widths)
            .enumerate()
            .map(|(i, (c, w))| {
                if i == 0 {
                    format!("{c:<w$}")
                } else {
                    format!("{c:>w$}")
                }
            })
            .collect();
        println!("{}", cells.join("  ").trim_end());
    }
}

fn short(name: &str) -> &str {
    name.trim_end_matches(".csv")
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Summary {
            log,
            json,
            budget_ms,
        } => {
            let log = read(&log)?;
            notes(&log);
            let stats = Stats::of(&log, budget_ms);
            if json {
                println!("{}", serde_json::to_string_pretty(&stats)?);
            } else {
                print_table(std::slice::from_ref(&stats));
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Compare {
            logs,
            json,
            plot,
            fail_if_slower,
            budget_ms,
        } => {
            let logs: Vec<FrameLog> = logs.iter().map(|p| read(p)).collect::<Result<_, _>>()?;
            for l in &logs {
                notes(l);
            }
            if logs.iter().any(|l| l.frames != logs[0].frames) {
                eprintln!("frametimes: note: the logs have different frame counts; figures compare distributions, not frame by frame");
            }
            let stats: Vec<Stats> = logs.iter().map(|l| Stats::of(l, budget_ms)).collect();
            let comparisons: Vec<Comparison> =
                logs.iter().skip(1).map(|l| compare(&logs[0], l)).collect();
            if json {
                let value = serde_json::json!({ "logs": stats, "comparisons": comparisons });
                println!("{}", serde_json::to_string_pretty(&value)?);
            } else {
                print_table(&stats);
                println!();
                for c in &comparisons {
                    println!("{}", c.verdict());
                }
            }
            if let Some(out) = plot {
                frametimes::plot::plot(&logs, &out, budget_ms)?;
                if !json {
                    println!("plot: {}", out.display());
                }
            }
            if let Some(percent) = fail_if_slower {
                let slower: Vec<&Comparison> = comparisons
                    .iter()
                    .filter(|c| c.slower_by_more_than(percent))
                    .collect();
                if !slower.is_empty() {
                    for c in slower {
                        eprintln!(
                            "frametimes: {} is slower than {} by more than {percent}% beyond noise",
                            c.other, c.baseline
                        );
                    }
                    return Ok(ExitCode::from(3));
                }
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}
