#!/usr/bin/env bash
# Runs a distributed tiletool build on Kubernetes: the shards (build-job.yaml), then, once
# every shard is done, the merge (merge-job.yaml). Kubernetes has no dependencies between
# Jobs, so this script is the dependency: it waits for the build Job to end, and creates the
# merge only if the build completed.
#
#   deploy/kubernetes/run.sh          create the build Job, wait, then merge
#   deploy/kubernetes/run.sh rerun    after a failed build: delete the build Job (ending any
#                                     pod it still has, and waiting until they have stopped),
#                                     create it again with SKIP_COMPLETE=1, so that only the
#                                     shards without a complete part build again; wait; merge
#   deploy/kubernetes/run.sh merge    only the merge (the build Job must be Complete)
#
# Env: NAMESPACE (default: kubectl's current one), BUILD_TIMEOUT_S [86400],
#      MERGE_TIMEOUT_S [21600], POLL_S [15]. SCAN=1 (run only): before the build Job, two
#      Indexed Jobs made from build-job.yaml, vkterrain-scan (STAGE=scan) and then
#      vkterrain-ranges (STAGE=ranges), each waited for; the build Job then runs with
#      SCANS=1, so that each shard reads only its rows of the input (README.md here).
# Needs a cluster >= 1.29 (build-job.yaml) and kubectl >= 1.29: `kubectl set env --local`
# passes the Job through kubectl's own types, and an older one drops the fields it lacks.
#
# Why not `kubectl apply` and `kubectl wait --for=condition=complete`: apply of a Job that
# exists and has finished changes nothing (no new run), and `kubectl wait` for Complete does
# not return when the Job fails: it waits out its timeout. So: create, and poll for either.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
BUILD=vkterrain-build
MERGE=vkterrain-merge
BUILD_TIMEOUT_S=${BUILD_TIMEOUT_S:-86400}
MERGE_TIMEOUT_S=${MERGE_TIMEOUT_S:-21600}
POLL_S=${POLL_S:-15}

k() { kubectl ${NAMESPACE:+--namespace "$NAMESPACE"} "$@"; }
say() { echo "run.sh: $*" >&2; }

# conditions NAME: the Job's conditions that hold, e.g. "SuccessCriteriaMet Complete ".
conditions() {
  k get job "$1" -o jsonpath='{range .status.conditions[?(@.status=="True")]}{.type}{" "}{end}'
}

# wait_job NAME TIMEOUT_S: 0 when the Job is Complete, 1 when it Failed, 2 when the time ran
# out first (the Job goes on).
# (Complete and Failed are the terminal conditions: set once the Job's pods have stopped.)
wait_job() {
  local name=$1 deadline=$((SECONDS + $2)) state
  say "waiting for job/$name (at most $2 s)"
  while :; do
    state=$(conditions "$name")
    case " $state " in
      *" Complete "*) say "job/$name complete"; return 0 ;;
      *" Failed "*) say "job/$name failed"; return 1 ;;
    esac
    if ((SECONDS >= deadline)); then
      say "job/$name still running after $2 s; no longer waiting for it (it goes on)"
      return 2
    fi
    sleep "$POLL_S"
  done
}

# The fields of build-job.yaml that a cluster without the feature drops silently.
check_features() {
  local per_index
  per_index=$(k get job "$BUILD" -o jsonpath='{.spec.backoffLimitPerIndex}')
  if [ -z "$per_index" ]; then
    say "warning: the cluster dropped spec.backoffLimitPerIndex (Kubernetes < 1.29, or the" \
      "JobBackoffLimitPerIndex feature off): retries count against one backoffLimit for" \
      "all shards, and status.failedIndexes stays empty"
  fi
}

report_build_failure() {
  local failed completed
  failed=$(k get job "$BUILD" -o jsonpath='{.status.failedIndexes}')
  completed=$(k get job "$BUILD" -o jsonpath='{.status.completedIndexes}')
  say "completed indexes: ${completed:-none}; failed indexes: ${failed:-none}"
  k get job "$BUILD" \
    -o jsonpath='{range .status.conditions[*]}{.type}={.status} {.reason}: {.message}{"\n"}{end}' >&2 || true
  say "logs of a failed index K (the pods of a failed Job are kept until it is deleted):"
  say "  kubectl logs -l batch.kubernetes.io/job-name=$BUILD,batch.kubernetes.io/job-completion-index=K --prefix --tail=20"
  say "fix the cause (OOMKilled: raise the memory limit in build-job.yaml), then rebuild only"
  say "the shards without a complete part: $0 rerun"
}

# create_build [SKIP_COMPLETE value]: the build Job (with SCANS=1 after the scan stages).
create_build() {
  local envs=()
  [ "${1:-0}" = 1 ] && envs+=(SKIP_COMPLETE=1)
  [ "${SCAN:-0}" = 1 ] && envs+=(SCANS=1)
  if [ ${#envs[@]} -gt 0 ]; then
    kubectl set env --local -f "$here/build-job.yaml" "${envs[@]}" -o yaml | k create -f -
  else
    k create -f "$here/build-job.yaml"
  fi
  check_features
}

# stage scan|ranges: the build Job's manifest as vkterrain-STAGE with STAGE set, created and
# waited for; exits when it does not complete.
stage() {
  local name=vkterrain-$1 rc=0
  k delete job "$name" --ignore-not-found --cascade=foreground --wait=true
  kubectl set env --local -f "$here/build-job.yaml" STAGE="$1" -o yaml |
    sed "s/^  name: $BUILD\$/  name: $name/" | k create -f -
  wait_job "$name" "$BUILD_TIMEOUT_S" || rc=$?
  if [ "$rc" != 0 ]; then
    say "job/$name did not complete; its failed indexes' logs:"
    say "  kubectl logs -l batch.kubernetes.io/job-name=$name --prefix --tail=20"
    exit 1
  fi
}

build() {
  local rc=0
  wait_job "$BUILD" "$BUILD_TIMEOUT_S" || rc=$?
  case $rc in
    0) ;;
    1) report_build_failure; exit 1 ;;
    *) say "when it has ended: \`$0 merge\` if it is Complete, \`$0 rerun\` if it Failed"
       exit 1 ;;
  esac
}

merge() {
  # A merge Job from an earlier run: remove it, and wait until its pod has stopped.
  k delete job "$MERGE" --ignore-not-found --cascade=foreground --wait=true
  k create -f "$here/merge-job.yaml"
  local rc=0
  wait_job "$MERGE" "$MERGE_TIMEOUT_S" || rc=$?
  if [ "$rc" = 1 ]; then
    say "the merge failed; its last lines (README.md, \"The merge's errors\"):"
    k logs "job/$MERGE" --tail=5 >&2 || true
  fi
  [ "$rc" = 0 ] || exit 1
  k logs "job/$MERGE" --tail=20 >&2 || true
}

case ${1:-run} in
  run)
    if k get job "$BUILD" >/dev/null 2>&1; then
      say "job/$BUILD exists from an earlier run: \`$0 rerun\` rebuilds the shards without a"
      say "complete part; or delete it (kubectl delete job $BUILD --cascade=foreground) first"
      exit 1
    fi
    if [ "${SCAN:-0}" = 1 ]; then
      stage scan
      stage ranges
    fi
    create_build 0
    build
    merge
    ;;
  rerun)
    k delete job "$BUILD" --ignore-not-found --cascade=foreground --wait=true
    create_build 1
    build
    merge
    ;;
  merge)
    state=$(conditions "$BUILD")
    case " $state " in
      *" Complete "*) ;;
      *) say "job/$BUILD is not Complete (conditions: ${state:-none})"; exit 1 ;;
    esac
    merge
    ;;
  *)
    echo "usage: $0 [run|rerun|merge]" >&2
    exit 2
    ;;
esac
say "done: the set is OUTPUT of merge-job.yaml (/parts/set.vkt on vkterrain-parts)"
