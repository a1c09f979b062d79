//! `memsim`: replays a `vkterrain --trace` file through every residency policy.
//!
//! ```text
//! memsim TRACE.csv [--pool-share 0.25 | --pool-mb MB] [--upload-budget-mb 4]
//! memsim TRACE.csv --time-manager
//! ```
//!
//! `--time-manager` times the manager instead, on a synthetic flight of 1000 visible tiles
//! built from the trace's tile costs (see `memory::sim::synthetic`).

use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use bench::residency::{
    bytes_by_scheme, policy_runs, policy_table, tile_set_figures, time_manager,
};
use memory::sim::tile_set_bytes;
use memory::trace::Trace;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("memsim: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().filter(|a| !a.starts_with('-')) else {
        bail!("usage: memsim TRACE.csv [--pool-share F | --pool-mb MB] [--upload-budget-mb MB] [--perfect-frames N] [--index-arrays built|sent] | --time-manager");
    };
    let flag = |name: &str| -> Result<Option<f64>> {
        match args.iter().position(|a| a == name) {
            None => Ok(None),
            Some(i) => {
                let v: f64 = args
                    .get(i + 1)
                    .and_then(|v| v.parse().ok())
                    .filter(|v: &f64| v.is_finite() && *v > 0.0)
                    .with_context(|| format!("{name} needs a positive number"))?;
                Ok(Some(v))
            }
        }
    };
    let text = std::fs::read_to_string(path).with_context(|| format!("{path}: cannot read"))?;
    let trace = Trace::parse(&text).map_err(|e| anyhow::anyhow!("{path}: {e}"))?;
    if args.iter().any(|a| a == "--time-manager") {
        let (frames, times, evictions) = time_manager(&trace.costs);
        let p = |q: f64| frametimes::stats::percentile(&times, q);
        println!(
            "manager: {frames} frames of 1000 visible tiles: median {:.3} ms, p95 {:.3} ms, max {:.3} ms, {evictions} evictions",
            p(50.0),
            p(95.0),
            times.last().copied().unwrap_or(f64::NAN)
        );
        return Ok(());
    }
    let total = tile_set_bytes(&trace);
    let pool = match (flag("--pool-mb")?, flag("--pool-share")?) {
        (Some(mb), _) => (mb * 1e6) as u64,
        (None, share) => (total as f64 * share.unwrap_or(0.25)) as u64,
    };
    let upload = flag("--upload-budget-mb")?.map_or(memory::DEFAULT_UPLOAD_BUDGET, |mb| {
        (mb * f64::from(1 << 20)) as u64
    });
    let (refine, scratch, whole) = tile_set_figures(&trace);
    println!(
        "{path}: {} frames, {} tiles, tile set {:.1} MB (finest level: refine {:.1} MB, from scratch {:.1} MB, whole {:.1} MB)\n",
        trace.frames.len(),
        trace.costs.len(),
        total as f64 / 1e6,
        refine as f64 / 1e6,
        scratch as f64 / 1e6,
        whole as f64 / 1e6
    );
    let [w, p, g] = bytes_by_scheme(&trace);
    println!(
        "Room for everything: whole tiles {:.1} MB, per level from scratch {:.1} MB, progressive {:.1} MB ({:.0}% indices)\n",
        w.bytes() as f64 / 1e6,
        p.bytes() as f64 / 1e6,
        g.bytes() as f64 / 1e6,
        100.0 * g.bytes_indices as f64 / (g.bytes() as f64).max(1.0)
    );
    println!(
        "Pool {:.1} MB, upload budget {:.1} MB per frame:\n",
        pool as f64 / 1e6,
        upload as f64 / 1e6
    );
    print!("{}", policy_table(&policy_runs(&trace, pool, upload)));
    println!("\nDowngrade slack (room for everything): a tile may stay drawn up to N levels finer than wanted rather than re-sending an index array\n");
    for slack in [0, 1, 2, 9] {
        let c = memory::Config {
            pool_bytes: u64::MAX / 4,
            upload_budget: u64::MAX / 4,
            downgrade_slack: slack,
            ..memory::Config::default()
        };
        let o = memory::sim::replay(&trace, c, 2);
        println!("- slack {slack}: {:.1} MB uploaded", o.bytes() as f64 / 1e6);
    }
    // vkterrain looks at least 8 frames ahead (renderer::prefetch::predict::HORIZON_FRAMES); more at
    // interactive frame rates, where 2 s is longer.
    let ahead = flag("--perfect-frames")?.map_or(8, |f| f as usize);
    // As the renderer: index arrays built on the GPU unless told they are sent.
    let arrays = match args
        .iter()
        .position(|a| a == "--index-arrays")
        .map(|i| args.get(i + 1).map(String::as_str))
    {
        None | Some(Some("built")) => memory::IndexArrays::Built,
        Some(Some("sent")) => memory::IndexArrays::Sent,
        Some(other) => bail!("--index-arrays needs built or sent, not {other:?}"),
    };
    println!("\nPrefetching (pool {:.1} MB, upload budget {:.2} MB per frame, index arrays {arrays:?}; perfect: the next {ahead} frames' requests)\n", pool as f64 / 1e6, upload as f64 / 1e6);
    print!(
        "{}",
        bench::residency::prefetch_table(&trace, pool, upload, ahead, arrays)
    );
    Ok(())
}
