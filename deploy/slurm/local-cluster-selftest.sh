#!/usr/bin/env bash
# Self-test for local-cluster.sh: array job + dependency, cancel one array task,
# double start, stop, restart, double stop.   Usage: local-cluster-selftest.sh [STATE_DIR]
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
LC=$HERE/local-cluster.sh
D=${1:-$(mktemp -d /tmp/slurm-selftest.XXXXXX)}
fail() { echo "FAIL: $*" >&2; "$LC" stop "$D" || true; exit 1; }

# wait_gone JOBID...: poll squeue until none of the jobs is pending/running (max 120 s).
wait_gone() {
  local i
  for i in $(seq 240); do
    [ -z "$(squeue -h -j "$(IFS=,; echo "$*")" -o %i 2>/dev/null)" ] && return 0
    sleep 0.5
  done
  squeue; fail "jobs $* still queued"
}
# job_state JOBID: JobState from scontrol (works for finished jobs until MinJobAge).
job_state() { scontrol show job "$1" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' | head -n1; }

t0=$SECONDS
out=$("$LC" start "$D") || fail "start"
echo "$out"; echo "start took $((SECONDS - t0)) s"
eval "export $(echo "$out" | grep '^SLURM_CONF=')"
pids=$(cat "$D"/run/*.pid)
"$LC" start "$D" >/dev/null || fail "second start"
[ "$(cat "$D"/run/*.pid)" = "$pids" ] || fail "second start restarted daemons"

# 1) array job + afterok dependency
arr=$(sbatch --parsable --array=0-3 --output="$D/out-%A_%a.txt" \
  --wrap 'echo $SLURM_ARRAY_TASK_ID $SLURM_ARRAY_TASK_COUNT; sleep 2')
dep=$(sbatch --parsable --dependency=afterok:"$arr" --output="$D/merged-%j.txt" --wrap 'echo merged')
t1=$SECONDS; wait_gone "$arr" "$dep"; echo "array+dep finished in $((SECONDS - t1)) s"
for i in 0 1 2 3; do
  [ "$(cat "$D/out-${arr}_$i.txt")" = "$i 4" ] || fail "out-${arr}_$i.txt: $(cat "$D/out-${arr}_$i.txt")"
done
[ "$(cat "$D/merged-$dep.txt")" = merged ] || fail "merged output"
[ "$(job_state "$dep")" = COMPLETED ] || fail "dep state $(job_state "$dep")"
echo "OK array+dependency ($arr, $dep)"

# 2) cancel one array task while it runs
c=$(sbatch --parsable --array=0-1 --output="$D/c-%A_%a.txt" --wrap 'sleep 30')
for i in $(seq 120); do [ "$(job_state "${c}_1")" = RUNNING ] && break; sleep 0.5; done
[ "$(job_state "${c}_1")" = RUNNING ] || fail "task 1 never RUNNING"
scancel "${c}_1"
for i in $(seq 60); do [ "$(job_state "${c}_1")" = CANCELLED ] && break; sleep 0.5; done
[ "$(job_state "${c}_1")" = CANCELLED ] || fail "task 1 state $(job_state "${c}_1")"
[ "$(job_state "${c}_0")" = RUNNING ] || fail "task 0 not running after cancel of task 1"
wait_gone "$c"
[ "$(job_state "${c}_0")" = COMPLETED ] || fail "task 0 state $(job_state "${c}_0")"
echo "OK cancel ($c: _0 COMPLETED, _1 CANCELLED)"

# 3) stop, restart, job after restart, stop twice
pids=$(cat "$D"/run/*.pid); "$LC" stop "$D"
for p in $pids; do  # zombies (not yet reaped by PID 1) count as stopped
  [[ $(ps -o stat= -p "$p" || echo Z) == Z* ]] || fail "pid $p still running after stop"
done
t0=$SECONDS; "$LC" start "$D" || fail "restart"; echo "restart took $((SECONDS - t0)) s"
r=$(sbatch --parsable --output="$D/r-%j.txt" --wrap 'echo again'); wait_gone "$r"
[ "$(cat "$D/r-$r.txt")" = again ] || fail "job after restart"
echo "OK restart"
"$LC" stop "$D"; "$LC" stop "$D"
echo "ALL OK ($D)"
