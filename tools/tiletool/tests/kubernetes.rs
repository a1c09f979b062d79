//! The Kubernetes side of distributed builds (issue 29), tested without a cluster: the
//! container's entrypoint (`deploy/kubernetes/entrypoint.sh`) run as an Indexed Job's pods
//! would run it, with `JOB_COMPLETION_INDEX` and `SHARDS` set, around the real tiletool, and
//! its merge mode: the set is the build's bytes. Then `deploy/kubernetes/check.sh`: the
//! entrypoint's refusals against a fake tiletool, and the manifests parsed as YAML
//! (`completionMode: Indexed`, `backoffLimitPerIndex`, completions equal to SHARDS, the
//! shared volumes at the same paths, ...); a manifest broken on purpose must fail it.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{s, stderr, tiletool};
use testdata::data;

fn deploy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/kubernetes")
}

/// The entrypoint as a pod runs it: only the variables the manifests set.
fn entrypoint(vars: &[(&str, &str)], args: &[&str]) -> Output {
    Command::new("bash")
        .arg(deploy().join("entrypoint.sh"))
        .args(args)
        .env_clear()
        .env("PATH", std::env::var("PATH").unwrap_or_default())
        .env("TILETOOL", env!("CARGO_BIN_EXE_tiletool"))
        .envs(vars.iter().copied())
        .output()
        .expect("bash runs")
}

/// `input` built untextured without shards into `dir`/whole.vkt: what the shards must merge to.
fn built(input: &Path, dir: &Path) -> PathBuf {
    let whole = dir.join("whole.vkt");
    let o = tiletool(&[
        "build",
        s(input),
        "--no-texture",
        "--quiet",
        "-o",
        s(&whole),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    whole
}

/// The entrypoint's merge of the 3 parts in `work` into `dir`/set.vkt; whether the set is
/// `whole`'s bytes.
fn merges_to(work: &Path, dir: &Path, whole: &Path) -> bool {
    let set = dir.join("set.vkt");
    let vars = [("SHARDS", "3"), ("WORK_DIR", s(work)), ("OUTPUT", s(&set))];
    let o = entrypoint(&vars, &["merge"]);
    assert!(o.status.success(), "merge: {}", stderr(&o));
    std::fs::read(&set).expect("set") == std::fs::read(whole).expect("whole")
}

#[test]
fn the_entrypoint_maps_the_index_to_a_shard_and_merges_the_builds_bytes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = data("srtm/N55W003.hgt");
    let whole = built(&input, dir.path());
    let work = dir.path().join("parts");
    for k in 0..3 {
        let index = k.to_string();
        let vars = [
            ("JOB_COMPLETION_INDEX", index.as_str()),
            ("SHARDS", "3"),
            ("WORK_DIR", s(&work)),
        ];
        let o = entrypoint(&vars, &[s(&input), "--no-texture", "--quiet"]);
        assert!(o.status.success(), "pod {k}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(&format!("--shard {k}/3")),
            "pod {k} did not build shard {k}/3: {}",
            stderr(&o)
        );
        assert!(work.join(format!("part-{k}-of-3.vktpart")).exists());
    }
    assert!(
        merges_to(&work, dir.path(), &whole),
        "the merged set differs from the build without shards"
    );
    // A pod without its index is refused before any work.
    let o = entrypoint(&[("SHARDS", "3"), ("WORK_DIR", s(&work))], &[s(&input)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("JOB_COMPLETION_INDEX is not set"));
}

/// The scan stages as run.sh runs them with SCAN=1, each an Indexed Job's pods: STAGE=scan,
/// then STAGE=ranges, then the build with SCANS=1, over an input with voids (SRTM1
/// N48W125), then the merge: the set is the build's bytes.
#[test]
fn the_entrypoints_scan_stages_build_the_same_set() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = data("srtm/N48W125.hgt");
    let whole = built(&input, dir.path());
    let work = dir.path().join("parts");
    for (stage, scans) in [("scan", "0"), ("ranges", "0"), ("build", "1")] {
        for k in 0..3 {
            let index = k.to_string();
            let vars = [
                ("JOB_COMPLETION_INDEX", index.as_str()),
                ("SHARDS", "3"),
                ("WORK_DIR", s(&work)),
                ("STAGE", stage),
                ("SCANS", scans),
            ];
            let o = entrypoint(&vars, &[s(&input), "--no-texture", "--quiet"]);
            assert!(o.status.success(), "{stage} pod {k}: {}", stderr(&o));
        }
    }
    assert!(work.join("scans/ranges-2-of-3.vktranges").exists());
    assert!(
        merges_to(&work, dir.path(), &whole),
        "the set built in three stages differs from the build without shards"
    );
}

fn check(folder: &Path) -> (bool, String) {
    let o = Command::new("bash")
        .arg(folder.join("check.sh"))
        .output()
        .expect("bash runs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
    )
}

/// check.sh passes, with the manifests' checks run, not skipped (python3-yaml is installed by
/// .ci/setup); only the optional linters may be missing, and they are named. The control: a
/// build Job whose completions differ from SHARDS fails it.
#[test]
fn the_manifests_and_the_entrypoint_pass_their_checks_and_a_broken_manifest_does_not() {
    let (ok, said) = check(&deploy());
    assert!(ok, "deploy/kubernetes/check.sh failed:\n{said}");
    assert!(said.contains("ok    manifests agree"), "{said}");
    for skipped in said.lines().filter(|l| l.starts_with("skip")) {
        let optional = ["shellcheck", "hadolint", "kubernetes-validate", "yamllint"];
        assert!(
            optional.iter().any(|t| skipped.contains(t)),
            "a required check was skipped: {skipped}"
        );
        eprintln!("optional linter not installed: {skipped}");
    }
    let dir = tempfile::tempdir().expect("temp dir");
    for entry in std::fs::read_dir(deploy())
        .expect("deploy/kubernetes")
        .flatten()
    {
        std::fs::copy(entry.path(), dir.path().join(entry.file_name())).expect("copy");
    }
    let manifest = dir.path().join("build-job.yaml");
    let text = std::fs::read_to_string(&manifest).expect("read");
    assert!(
        text.contains("completions: 4"),
        "the control's edit no longer applies"
    );
    std::fs::write(&manifest, text.replace("completions: 4", "completions: 5")).expect("write");
    let (ok, said) = check(dir.path());
    assert!(!ok, "completions != SHARDS passed the checks:\n{said}");
    assert!(said.contains("completions == SHARDS"), "{said}");
}
