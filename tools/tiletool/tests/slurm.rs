//! A distributed build on a real Slurm (issue 29): a single-node cluster started on localhost
//! by `deploy/slurm/local-cluster.sh` (Debian's `slurm-wlm` and `munge`, installed by
//! `.ci/setup`), the 4K Puget DEM built as a 4-task array job with the merge depending on it
//! (`deploy/slurm/submit.sh`), compared byte for byte with the build without shards. Then one
//! array task is cancelled while it writes its part, leaves nothing, and only that index is
//! submitted again; the merge's set is again the build's. Last, an input with voids (SRTM1
//! N48W125) in the three stages `submit.sh` runs with SCAN=1: scan, ranges, build, then merge.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use common::{s, stderr, tiletool};
use testdata::data;

/// The 4K Puget DEM and the options it is built with: each shard runs for seconds, long
/// enough to be cancelled while it writes.
fn input_and_options() -> Vec<String> {
    let dem = data("puget/ps_height_4k_8bit.jpg");
    [
        s(&dem),
        "--spacing",
        "40",
        "--vertical-scale",
        "25.7",
        "--quiet",
    ]
    .map(String::from)
    .to_vec()
}

fn deploy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/slurm")
}

/// A cluster on localhost, stopped when dropped.
struct Cluster {
    state: tempfile::TempDir,
}

impl Cluster {
    fn start() -> Cluster {
        for tool in ["sbatch", "slurmctld", "slurmd", "munged"] {
            let found = Command::new("sh")
                .args(["-c", &format!("command -v {tool}")])
                .output()
                .expect("sh runs");
            assert!(
                found.status.success(),
                "{tool} is not installed: .ci/setup installs slurm-wlm and munge"
            );
        }
        // Unix socket paths under the state folder must stay short: /tmp, not the target dir.
        let state = tempfile::Builder::new()
            .prefix("vkt-slurm")
            .tempdir_in("/tmp")
            .expect("temp dir");
        let o = Command::new(deploy().join("local-cluster.sh"))
            .args(["start", s(state.path())])
            .output()
            .expect("local-cluster.sh runs");
        assert!(
            o.status.success(),
            "the local Slurm did not start: {}{}",
            String::from_utf8_lossy(&o.stdout),
            stderr(&o)
        );
        Cluster { state }
    }

    /// A Slurm command (or one of our scripts) against this cluster, run in `cwd`.
    fn run(&self, program: &Path, args: &[&str], cwd: &Path) -> Output {
        self.run_with(program, args, cwd, &[])
    }

    /// [`Cluster::run`] with more variables in its environment.
    fn run_with(&self, program: &Path, args: &[&str], cwd: &Path, env: &[(&str, &str)]) -> Output {
        Command::new(program)
            .args(args)
            .current_dir(cwd)
            .envs(env.iter().copied())
            .env("SLURM_CONF", self.state.path().join("slurm.conf"))
            .env("TILETOOL", env!("CARGO_BIN_EXE_tiletool"))
            .output()
            .expect("runs")
    }

    fn ok(&self, program: &str, args: &[&str], cwd: &Path) -> String {
        let o = self.run(Path::new(program), args, cwd);
        assert!(o.status.success(), "{program} {args:?}: {}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).trim().to_string()
    }

    /// Waits until `job` (an id, or `id_index`) has left the queue; returns its final state.
    fn wait(&self, job: &str, cwd: &Path) -> String {
        let start = Instant::now();
        loop {
            let queued = self.ok("squeue", &["-h", "-j", job, "-o", "%i %T"], cwd);
            if queued.is_empty() {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(600),
                "job {job} still queued: {queued}"
            );
            std::thread::sleep(Duration::from_millis(250));
        }
        self.state_of(job, cwd)
    }

    /// The job's state as `scontrol` reports it (finished jobs stay for MinJobAge).
    fn state_of(&self, job: &str, cwd: &Path) -> String {
        let shown = self.ok("scontrol", &["show", "job", job, "-o"], cwd);
        shown
            .split_whitespace()
            .find_map(|f| f.strip_prefix("JobState="))
            .unwrap_or("UNKNOWN")
            .to_string()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new(deploy().join("local-cluster.sh"))
            .args(["stop", s(self.state.path())])
            .output();
    }
}

fn same_bytes(a: &Path, b: &Path) -> bool {
    std::fs::read(a).expect("read") == std::fs::read(b).expect("read")
}

#[test]
fn a_slurm_array_builds_the_same_set_and_one_cancelled_index_is_rerun() {
    let dir = tempfile::tempdir().expect("temp dir");
    let work = dir.path().join("parts");
    let whole = dir.path().join("whole.vkt");
    let options = input_and_options();
    let mut args: Vec<&str> = vec!["build", "-o", s(&whole)];
    args.extend(options.iter().map(String::as_str));
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));

    let cluster = Cluster::start();
    let cwd = dir.path();
    let merged = dir.path().join("merged.vkt");
    let submit = deploy().join("submit.sh");
    let mut args = vec!["4", s(&work), s(&merged)];
    args.extend(options.iter().map(String::as_str));
    let ids = cluster.ok(s(&submit), &args, cwd);
    let (array, merge) = ids.split_once(' ').expect("two job ids");
    for k in 0..4 {
        let task = format!("{array}_{k}");
        assert_eq!(cluster.wait(&task, cwd), "COMPLETED", "shard {k}");
    }
    assert_eq!(cluster.wait(merge, cwd), "COMPLETED", "the merge");
    assert!(
        same_bytes(&merged, &whole),
        "the Slurm build differs from the build without shards"
    );

    // Shard 2 again, cancelled once it has started writing its part.
    let part = work.join("part-2-of-4.vktpart");
    std::fs::remove_file(&part).expect("rm part");
    std::fs::remove_file(&merged).expect("rm set");
    let build = deploy().join("build.sbatch");
    let mut args = vec!["--parsable", "--array=2", s(&build), "4", s(&work)];
    args.extend(options.iter().map(String::as_str));
    let rerun = cluster.ok("sbatch", &args, cwd);
    let writing = |w: &Path| {
        std::fs::read_dir(w).is_ok_and(|d| {
            d.flatten().any(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(".part-2-of-4.vktpart.tmp.")
            })
        })
    };
    let start = Instant::now();
    while !writing(&work) {
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "shard 2 never started writing"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let task = format!("{rerun}_2");
    cluster.ok("scancel", &[&task], cwd);
    assert_eq!(cluster.wait(&task, cwd), "CANCELLED", "the cancelled task");
    assert!(!part.exists(), "a cancelled shard left a part");
    assert!(!writing(&work), "a cancelled shard left its temporary file");
    // Without it, the merge refuses and names what is missing.
    let merge_script = deploy().join("merge.sbatch");
    let o = cluster.run(&merge_script, &["4", s(&work), s(&merged)], cwd);
    assert!(!o.status.success() && stderr(&o).contains("part-2-of-4.vktpart"));
    assert!(!merged.exists());

    // Only that index, submitted again, then the merge after it.
    let rerun = cluster.ok("sbatch", &args, cwd);
    let merge = cluster.ok(
        "sbatch",
        &[
            "--parsable",
            &format!("--dependency=afterok:{rerun}"),
            s(&merge_script),
            "4",
            s(&work),
            s(&merged),
        ],
        cwd,
    );
    assert_eq!(cluster.wait(&format!("{rerun}_2"), cwd), "COMPLETED");
    assert_eq!(cluster.wait(&merge, cwd), "COMPLETED", "the merge");
    assert!(
        same_bytes(&merged, &whole),
        "after the rerun the set differs from the build without shards"
    );

    // The three stages (SCAN=1: scan, ranges, build; then the merge) over an input with
    // voids, SRTM1 N48W125 in 3 shards: the set is the build's.
    let voids = data("srtm/N48W125.hgt");
    let options = [s(&voids), "--no-texture", "--quiet"];
    let whole = dir.path().join("n48.vkt");
    let mut args = vec!["build", "-o", s(&whole)];
    args.extend(options);
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let work = dir.path().join("n48-parts");
    let merged = dir.path().join("n48-merged.vkt");
    let mut args = vec!["3", s(&work), s(&merged)];
    args.extend(options);
    let o = cluster.run_with(&submit, &args, cwd, &[("SCAN", "1")]);
    assert!(o.status.success(), "submit.sh: {}", stderr(&o));
    let ids = String::from_utf8_lossy(&o.stdout).trim().to_string();
    let (array, merge) = ids.split_once(' ').expect("two job ids");
    for k in 0..3 {
        let task = format!("{array}_{k}");
        assert_eq!(cluster.wait(&task, cwd), "COMPLETED", "N48W125 shard {k}");
        let ranges = work.join(format!("scans/ranges-{k}-of-3.vktranges"));
        assert!(ranges.exists(), "no {}", ranges.display());
    }
    assert_eq!(cluster.wait(merge, cwd), "COMPLETED", "the N48W125 merge");
    assert!(
        same_bytes(&merged, &whole),
        "N48W125 built in three stages on Slurm differs from the build without shards"
    );
}
