#!/usr/bin/env bash
# Prefetching (issue 10): tile-frames drawn coarser than wanted with and without prefetching
# under a tight per-frame upload budget (in all, and after the cold start: before the first
# frame that draws everything at its wanted level there is no history to predict from), p99
# frame time, bytes prefetched and wasted; the same flights' traces replayed by the simulator
# with our recorded predictions and with a perfect predictor; and a first flight from a cold
# page cache with and without madvise.
# Usage: bench/prefetch.sh TILESET [BUDGET_MB] [FRAMES] [--no-cold]   (after cargo build --release)
# INDEX_ARRAYS=sent sends index arrays from the file instead of building them on the GPU.
set -euo pipefail
set_file=$1; budget=${2:-1}; frames=${3:-120}; cold=${4:-}; arrays=${INDEX_ARRAYS:-built}
bin=$(dirname "$0")/../target/release
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
common=(--headless --size 1024x768 --frames "$frames" --tau 1 --upload-budget-mb "$budget" --index-arrays "$arrays")
echo "| path | prefetch | tile-frames coarser | after the cold start (frames) | p99 frame ms | prefetched MB | hits | wasted MB | prediction error m (median) | prefetch CPU ms (median) |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"
for path in orbit flyover; do
  for mode in on off; do
    extra=(); [ "$mode" = off ] && extra=(--no-prefetch)
    "$bin/vkterrain" "$set_file" "${common[@]}" --path "$path" "${extra[@]}" \
      --trace "$out/$path-$mode.trace" --log "$out/$path-$mode.csv" > "$out/$path-$mode.json" 2>/dev/null
  done
  python3 - "$out/$path-on.json" "$out/$path-off.json" "$path" <<'PY'
import json, sys
on, off = (json.load(open(f)) for f in sys.argv[1:3])
for mode, s in (("on", on), ("off", off)):
    e = s['prediction_error_m_median']
    print(f"| {sys.argv[3]} | {mode} | {s['tiles_coarser']} | {s['tiles_coarser_warm']} ({s['warmup_frames']}) "
          f"| {s['frame_ms_p99']:.1f} | {s['prefetch_mb']:.2f} | {s['prefetch_hits']} | {s['prefetch_wasted_mb']:.2f} "
          f"| {'-' if e is None else f'{e:.0f}'} | {s['cpu_prefetch_ms_median']:.2f} |")
ratio = lambda a, b: f"{a / b:.2f}" if b else "-"
print(f"| {sys.argv[3]} | on / off | {ratio(on['tiles_coarser'], off['tiles_coarser'])} "
      f"| {ratio(on['tiles_coarser_warm'], off['tiles_coarser_warm'])} | {ratio(on['frame_ms_p99'], off['frame_ms_p99'])} | | | | | |")
PY
done
echo
for path in orbit flyover; do
  echo "**Simulator, $path** (the trace of the run with prefetching, replayed with the pool as large as the set)"
  echo
  "$bin/memsim" "$out/$path-on.trace" --pool-mb 100000 --upload-budget-mb "$budget" --index-arrays "$arrays" | sed -n '/^| prefetching/,$p'
  echo
done
[ "$cold" = --no-cold ] && exit 0
echo "**Cold page cache** (the tile set dropped from the page cache after opening: madvise(DONTNEED) on the mapping, then posix_fadvise(DONTNEED) on the file; two runs each, alternating)"
echo
echo "| run | madvise | bytes still cached at start | frame 0 ms | p99 frame ms |"
echo "|---|---|---:|---:|---:|"
for round in 1 2; do
  for mode in on off; do
    extra=(); [ "$mode" = off ] && extra=(--no-madvise)
    "$bin/vkterrain" "$set_file" "${common[@]}" --path flyover --cold-file-cache "${extra[@]}" \
      --log "$out/cold.csv" > "$out/cold.json" 2> "$out/cold.err"
    left=$(grep -o '[0-9]* of' "$out/cold.err" | head -1 | cut -d' ' -f1)
    python3 - "$out/cold.json" "$out/cold.csv" "$round" "$mode" "$left" <<'PY'
import json, sys, csv
s = json.load(open(sys.argv[1])); rows = list(csv.DictReader(open(sys.argv[2])))
print(f"| {sys.argv[3]} | {sys.argv[4]} | {sys.argv[5]} | {float(rows[0]['frame_ms']):.1f} | {s['frame_ms_p99']:.1f} |")
PY
  done
done
