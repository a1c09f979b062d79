#!/usr/bin/env bash
# Container entrypoint for a sharded `tiletool build` on Kubernetes (see README.md here).
#
#   entrypoint.sh [build] INPUT... [BUILD-OPTIONS]   one shard: Indexed Job pod
#   entrypoint.sh merge [OUTPUT]                     join the parts: one pod, after the build
#
# Build: shard K of N, K = $JOB_COMPLETION_INDEX (set by Kubernetes in an Indexed Job's
# pods), N = $SHARDS (set in the manifest; must equal the Job's `completions`). Runs
#   $TILETOOL build INPUT... [BUILD-OPTIONS] --shard K/N -o $WORK_DIR/part-K-of-N.vktpart
# The part is written to a temporary name and renamed when complete, so a part under
# its name is whole; a retried shard replaces it.
# Merge: runs `$TILETOOL merge` over part-0-of-N ... part-(N-1)-of-N in $WORK_DIR with
#   -o OUTPUT (the second argument, else $OUTPUT).
# Scan stages (STAGE, build mode only): so that each shard reads only its rows of the input,
# an Indexed Job with STAGE=scan, then one with STAGE=ranges, run before the build Job with
# SCANS=1 (run.sh does this with SCAN=1; README.md here):
#   STAGE=scan    $TILETOOL build INPUT... --shard K/N --scan-only
#                   -o $WORK_DIR/scans/scan-K-of-N.vktscan
#   STAGE=ranges  $TILETOOL build INPUT... --shard K/N --scans $WORK_DIR/scans --ranges-only
#                   -o $WORK_DIR/scans/ranges-K-of-N.vktranges
#   SCANS=1       the build adds --scans $WORK_DIR/scans
#
# Env:
#   JOB_COMPLETION_INDEX  K (build only): a non-negative integer below SHARDS
#   SHARDS                N: a positive integer
#   WORK_DIR              folder of the parts, shared by all pods [/work/parts]
#   TILETOOL              the tiletool binary [tiletool, on PATH]
#   OUTPUT                the merged set (merge only, unless given as the second argument)
#   SKIP_COMPLETE         1: build mode exits 0 without building when the shard's part is
#                         already there and ends with the part's end mark (for re-running a
#                         Job after some indexes failed). The merge checks every part's
#                         checksum and recipe anyway. 0 or unset: always build.
#   STAGE                 scan, ranges or build [build]
#   SCANS                 1: the build reads every shard's scan (and ranges) from
#                         $WORK_DIR/scans; 0 or unset: it scans the whole input itself
# Refusals (bad env or arguments) print one line on stderr and exit 2; a merge with parts
# missing lists the missing shards and exits 1.
set -euo pipefail

WORK_DIR=${WORK_DIR:-/work/parts}
TILETOOL=${TILETOOL:-tiletool}

refuse() { echo "entrypoint: $*" >&2; exit 2; }

# The value of env var $1 as a decimal integer (no sign, no leading zeros, at most 9 digits,
# so that bash arithmetic and tiletool's u32 both take it), or a refusal naming it.
integer_env() {
  local name=$1 value=${!1-}
  [ -n "${!1+set}" ] || refuse "$name is not set"
  [[ $value =~ ^(0|[1-9][0-9]{0,8})$ ]] ||
    refuse "$name='$value' is not a non-negative integer (decimal, no leading zeros)"
  printf '%s\n' "$value"
}

# Prints the command on stderr, shell-quoted, then replaces this shell with it (so that
# tiletool gets the pod's SIGTERM and removes its temporary file).
run() {
  local quoted
  quoted=$(printf '%q ' "$@")
  echo "entrypoint: running: ${quoted% }" >&2
  exec "$@"
}

part_name() { printf '%s/part-%s-of-%s.vktpart\n' "$WORK_DIR" "$1" "$2"; }

mode=build
case ${1-} in
  merge) mode=merge; shift ;;
  build) shift ;;
esac

N=$(integer_env SHARDS)
[ "$N" -ge 1 ] || refuse "SHARDS=$N: must be at least 1"

case ${SKIP_COMPLETE:-0} in
  0) skip_complete=false ;;
  1) skip_complete=true ;;
  *) refuse "SKIP_COMPLETE='$SKIP_COMPLETE': must be 1 or 0" ;;
esac
case ${STAGE:-build} in
  scan | ranges | build) stage=${STAGE:-build} ;;
  *) refuse "STAGE='$STAGE': must be scan, ranges or build" ;;
esac
case ${SCANS:-0} in
  0) scans=() ;;
  1) scans=(--scans "$WORK_DIR/scans") ;;
  *) refuse "SCANS='$SCANS': must be 1 or 0" ;;
esac

if [ "$mode" = merge ]; then
  [ $# -le 1 ] || refuse "merge takes at most one argument, the output; got $#: $*"
  out=${1:-${OUTPUT:-}}
  [ -n "$out" ] || refuse "merge needs the output set: set OUTPUT or give it after 'merge'"
  parts=() missing=()
  for ((k = 0; k < N; k++)); do
    parts+=("$(part_name "$k" "$N")")
    [ -e "${parts[k]}" ] || missing+=("$k")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "entrypoint: merge: ${#missing[@]} of $N parts missing in $WORK_DIR: shards" \
      "${missing[*]} (build those indexes again)" >&2
    exit 1
  fi
  run "$TILETOOL" merge "${parts[@]}" -o "$out"
fi

[ $# -ge 1 ] || refuse "no input: give the input file(s) and build options as arguments"
K=$(integer_env JOB_COMPLETION_INDEX)
[ "$K" -lt "$N" ] ||
  refuse "JOB_COMPLETION_INDEX=$K is not below SHARDS=$N (the Job's completions must equal SHARDS)"

case $stage in
  scan)
    mkdir -p "$WORK_DIR/scans"
    run "$TILETOOL" build "$@" --shard "$K/$N" --scan-only \
      -o "$WORK_DIR/scans/scan-$K-of-$N.vktscan" ;;
  ranges)
    run "$TILETOOL" build "$@" --shard "$K/$N" --scans "$WORK_DIR/scans" --ranges-only \
      -o "$WORK_DIR/scans/ranges-$K-of-$N.vktranges" ;;
esac

part=$(part_name "$K" "$N")
if $skip_complete && [ -f "$part" ] &&
  [ "$(head -c 7 "$part")" = VKTPART ] && [ "$(tail -c 8 "$part" | tr -d '\0')" = VKTPEND ]; then
  echo "entrypoint: shard $K/$N: $part is already there and complete; not building it" \
    "again (SKIP_COMPLETE=1; the merge checks it)" >&2
  exit 0
fi

mkdir -p "$WORK_DIR"
run "$TILETOOL" build "$@" --shard "$K/$N" "${scans[@]}" -o "$part"
