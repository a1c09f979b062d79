#!/bin/bash
# A tile's levels checked as they are first needed, binaries side by side (`BINS`, default:
# this build's vkterrain alone). Per set, flight and binary, tau 1 with the defaults
# (geomorphing; `--pyramid` where the set has a pyramid, PYRAMID=0 to fly its base grid): the
# open (the summary's `open_ms`), the time a process takes to open the set and draw one frame
# (file warm, best of 2) and that first view's checks; then 60 frames at 1024 x 768 over the
# whole path: the checks made on the frames (tiles, ms in all; the median frame's after frame
# 5 and the largest frame's), the median frame after frame 5 and the largest. Sets as bench/pyramid.sh makes them (GENERATED mirror sets of SRTM3 N55W003) or
# any other, e.g. the demo's out/puget.vkt.
# usage: BINS="old/vkterrain target/release/vkterrain" bench/level_checks.sh SET.vkt...
set -euo pipefail
out=${OUT:-/tmp/level-checks-bench}; mkdir -p "$out"
bins=${BINS:-target/release/vkterrain}
echo "| set | flight | binary | open | to first frame | first view checked | checked on the frames: tiles, ms | median frame's checks, largest's, ms | frame ms: median, largest |"
echo "|---|---|---|---:|---:|---:|---:|---:|---:|"
for vkt in "$@"; do
  name=$(basename "$vkt" .vkt)
  flags=""
  if [ "${PYRAMID:-1}" = 1 ] && target/release/tiletool info "$vkt" --json 2>/dev/null \
      | python3 -c 'import json,sys; sys.exit(0 if json.load(sys.stdin).get("pyramid") else 1)'; then
    flags="--pyramid"
  fi
  for path in orbit flyover; do
    for bin in $bins; do
      run="$out/$name.$path.$(echo "$bin" | tr / _)"
      first=$(bench/first_frame.sh "$bin" "$vkt" $path "$run" $flags)
      "$bin" "$vkt" --headless --path $path --frames 60 --size 1024x768 $flags \
        --log "$run.csv" > /dev/null 2>&1
      python3 - "$run" "$name" "$path" "$bin" "$flags" "$first" <<'PY'
import csv, json, statistics, sys
run, name, path, binary, flags, first = sys.argv[1:]
wall, checks, opened = map(float, first.split())
rows = list(csv.DictReader(open(f"{run}.csv")))
col = lambda c, rs=rows: [float(r[c] or 0) for r in rs]
frames = col("frame_ms", rows[5:])
tiles, ms = sum(col("tiles_checked")), sum(col("cpu_check_ms"))
label = name + (" (cut)" if flags else "")
checked = col("cpu_check_ms", rows[5:])
print(f"| {label} | {path} | `{binary}` | {opened:.1f} ms | {wall:.2f} s | {checks:.0f} ms "
      f"| {tiles:.0f}, {ms:.0f} | {statistics.median(checked):.1f}, {max(col('cpu_check_ms')):.0f} "
      f"| {statistics.median(frames):.1f}, {max(frames):.1f} |")
PY
    done
  done
done
