#!/usr/bin/env bash
# What leaving the morph rows on disk saves (issue 28, "refinement bytes"): each flight flown
# with the default (positions alone travel; the morph pass and the discrete shader read no
# stored offsets) and with `--morph-rows` (every block's rows sent and held, as before), the
# two alternating, at the default upload budget and at tight ones: block bytes sent,
# tile-frames drawn coarser than wanted, the pool's resident bytes, triangles, median frame.
# Usage: bench/morph_rows.sh SET.vkt...   (after cargo build --release; BUDGETS="4 0.5 0.25")
set -euo pipefail
V=target/release/vkterrain
budgets=${BUDGETS:-4 0.5 0.25}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "| set | flight | budget MiB | rows | block MB sent | tile-frames coarser | resident MB (largest) | triangles (median) | frame ms (median after frame 5) |"
echo "|---|---|---:|---|---:|---:|---:|---:|---:|"
for set in "$@"; do
  for path in flyover orbit; do
    for budget in $budgets; do
      for rows in no yes; do
        flag=(); [ $rows = yes ] && flag=(--morph-rows)
        $V "$set" --headless --path $path --frames 120 --size 1024x768 --tau 1 \
          --upload-budget-mb "$budget" "${flag[@]}" --log "$out/f.csv" > /dev/null
        python3 - "$out/f.csv" "$(basename "$set")" $path "$budget" $rows <<'PY'
import csv, statistics, sys
r = list(csv.DictReader(open(sys.argv[1])))
total = lambda k: sum(float(x[k]) for x in r)
med = lambda k, rows: statistics.median(float(x[k]) for x in rows)
print(f"| {sys.argv[2]} | {sys.argv[3]} | {sys.argv[4]} | {sys.argv[5]} | {total('upload_bytes_blocks') / 1e6:.2f} "
      f"| {total('tiles_coarser'):.0f} | {max(float(x['resident_bytes']) for x in r) / 1e6:.1f} "
      f"| {med('triangles', r):.0f} | {med('frame_ms', r[5:]):.1f} |")
PY
      done
    done
  done
done
