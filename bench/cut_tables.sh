#!/bin/bash
# Geomorphing over a pyramid's cut, binaries side by side (`BINS`, default: this build's
# vkterrain alone): per set, flight and binary, the geomorphing cut (tau 1, the defaults)
# against the discrete cut (`--no-geomorph`) of the same binary, 60 frames at 1024 x 768:
# medians after frame 5 of triangles and tiles drawn (of them above the base grid), the time a
# process takes to open the set and draw one frame (file warm; best of 2), and that first
# view's checks. Sets as bench/pyramid.sh makes them (GENERATED mirror sets of SRTM3 N55W003).
# usage: BINS="old/vkterrain target/release/vkterrain" bench/cut_tables.sh SET.vkt...
set -euo pipefail
out=${OUT:-/tmp/cut-tables-bench}; mkdir -p "$out"
bins=${BINS:-target/release/vkterrain}
echo "| set | flight | binary | drawn as | triangles | tiles (above base) | to first frame | first view checked |"
echo "|---|---|---|---|---:|---:|---:|---:|"
for vkt in "$@"; do
  name=$(basename "$vkt" .vkt)
  for path in orbit flyover; do
    for bin in $bins; do
      for mode in morph discrete; do
        flags="--pyramid"; [ $mode = discrete ] && flags="--pyramid --no-geomorph"
        run="$out/$name.$path.$mode.$(echo "$bin" | tr / _)"
        first=$(bench/first_frame.sh "$bin" "$vkt" $path "$run" $flags)
        "$bin" "$vkt" --headless --path $path --frames 60 --size 1024x768 $flags \
          --log "$run.csv" > /dev/null 2>&1
        python3 - "$run" "$name" "$path" "$bin" "$mode" "$first" <<'PY'
import csv, json, statistics, sys
run, name, path, binary, mode, first = sys.argv[1:]
wall, checks = map(float, first.split()[:2])
rows = list(csv.DictReader(open(f"{run}.csv")))[5:]
med = lambda c: statistics.median(float(r[c] or 0) for r in rows)
drawn = "geomorphing cut" if mode == "morph" else "discrete cut"
print(f"| {name} | {path} | `{binary}` | {drawn} | {med('triangles'):,.0f} "
      f"| {med('tiles_drawn'):.0f} ({med('tiles_above_base'):.0f}) | {wall:.2f} s | {checks:.0f} ms |")
PY
      done
    done
  done
done
