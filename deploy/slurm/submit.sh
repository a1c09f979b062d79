#!/usr/bin/env bash
# Submits a distributed tile-set build to Slurm: an array of N shards, and the merge, which
# runs once every shard has succeeded.
#
#   deploy/slurm/submit.sh N WORK_DIR OUTPUT INPUT... [tiletool build options]
#
# Prints the array's and the merge's job ids ("ARRAY MERGE"). Extra sbatch options (account,
# partition, time, CPUs and memory per task) go in SBATCH_ARGS, e.g.
# SBATCH_ARGS="--partition=batch --cpus-per-task=16 --mem=8G". THROTTLE=M runs at most M
# shards at once (`--array=0-(N-1)%M`). SCAN=1 first submits an array that scans each
# shard's rows and one that ranges them filled (each after the one before), so that each
# build task reads only its rows of the input, not the whole of it. Logs go to the current
# folder.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
[ $# -ge 4 ] || { echo "usage: $0 N WORK_DIR OUTPUT INPUT... [options]" >&2; exit 2; }
n=$1 work=$2 output=$3
shift 3
range="0-$((n - 1))${THROTTLE:+%$THROTTLE}"
after=()
if [ "${SCAN:-0}" = 1 ]; then
  # shellcheck disable=SC2086
  scan=$(sbatch --parsable ${SBATCH_ARGS:-} --export=ALL,STAGE=scan --array="$range" \
    "$here/build.sbatch" "$n" "$work" "$@")
  # shellcheck disable=SC2086
  ranges=$(sbatch --parsable ${SBATCH_ARGS:-} --export=ALL,STAGE=ranges --array="$range" \
    --dependency="afterok:${scan%%;*}" --kill-on-invalid-dep=yes \
    "$here/build.sbatch" "$n" "$work" "$@")
  after=(--dependency="afterok:${ranges%%;*}" --kill-on-invalid-dep=yes --export=ALL,SCANS=1)
fi
# shellcheck disable=SC2086 # SBATCH_ARGS is a list of options
array=$(sbatch --parsable ${SBATCH_ARGS:-} "${after[@]}" --array="$range" \
  "$here/build.sbatch" "$n" "$work" "$@")
array=${array%%;*}
# If a shard fails, the dependency can never be met: the merge is cancelled rather than left
# pending, and is submitted again after that shard's rerun (README, "On Slurm").
merge=$(sbatch --parsable --dependency="afterok:$array" --kill-on-invalid-dep=yes \
  "$here/merge.sbatch" "$n" "$work" "$output")
echo "$array ${merge%%;*}"
