#!/bin/bash
# Index arrays made on the CPU against the GPU's builder, on lavapipe: issue 25's flights
# (the Puget 1K flyover and orbit from the demo's out/puget.vkt, the SRTM N48W125 flyover and
# orbit built here with the default options), 60 frames at 1024x768, discrete tau 1, geomorph
# tau 1 and 3, and brute force, each with `--index-builder gpu` then `cpu`, alternated within
# each round so that the machine's drift falls on both alike. Prints, per flight and mode, the
# median frame of each run (after frame 5) and the GPU time outside the draws, then the ratios
# within rounds (median over rounds).
#
#   cargo build --release -p tiletool -p renderer && bash .ci/demo   # out/puget.vkt
#   bench/made.sh [ROUNDS]                                            # default 2, ~6 min each
#   FLAG=--texture-format FROM=bc1 TO=rgb565 bench/made.sh            # another flag's values
#   BINARIES=1 FROM=OLD/vkterrain TO=NEW/vkterrain bench/made.sh      # two binaries
set -euo pipefail
rounds=${1:-2}
# shellcheck source=bench/issue25_sets.sh
source "$(dirname "$0")/issue25_sets.sh" /tmp/made-bench
FLAG=${FLAG:---index-builder}; FROM=${FROM:-gpu}; TO=${TO:-cpu}
rows=$out/rows.txt; : > "$rows"
for round in $(seq "$rounds"); do
  for flight in "${flights[@]}"; do
    set -- $flight
    for mode in "${modes[@]}"; do
      for builder in "$FROM" "$TO"; do
        # shellcheck disable=SC2086
        if [ -n "${BINARIES:-}" ]; then
          VK=$builder fly "$1" "$2" $mode
        else
          fly "$1" "$2" $mode $FLAG $builder
        fi
        python3 - "$round" "$(basename "$1" .vkt) $2" "$mode" "$builder" "$out/log.csv" >> "$rows" <<'PY'
import csv, sys
r = list(csv.DictReader(open(sys.argv[5])))[5:]
med = lambda f: sorted(f(x) for x in r)[len(r) // 2]
print("|".join(sys.argv[1:5] + [
    "%.2f" % med(lambda x: float(x["frame_ms"])),
    "%.2f" % med(lambda x: float(x["gpu_ms"]) - float(x["gpu_draw_ms"])),
    "%.2f" % med(lambda x: float(x["cpu_upload_ms"])),
    "%d" % med(lambda x: int(x["triangles"]) + int(x["stitch_triangles"])),
    "%d" % sum(int(x["index_arrays_made"]) for x in r),
]))
PY
      done
    done
  done
done
python3 - "$rows" "$FROM" "$TO" <<'PY'
import collections, statistics, sys
runs = collections.defaultdict(dict)
for l in open(sys.argv[1]):
    rnd, flight, mode, builder, frame, outside, upload, tris, made = l.rstrip("\n").split("|")
    runs[(flight, mode, builder)][int(rnd)] = (float(frame), float(outside), float(upload), int(tris), int(made))
keys = list(dict.fromkeys((f, m) for f, m, _ in runs))
a, b = sys.argv[2], sys.argv[3]
print(f"| flight | mode | frame ms, {a} (each round) | frame ms, {b} | outside the draws ms, {a} -> {b} | CPU upload ms, {a} -> {b} | triangles | arrays made ({b}) | {b} / {a} (median of rounds) |")
print("|---|---|---|---|---|---|---:|---:|---:|")
for f, m in keys:
    g, c = runs[(f, m, a)], runs[(f, m, b)]
    rs = sorted(set(g) & set(c))
    ratio = statistics.median(c[r][0] / g[r][0] for r in rs)
    med = lambda x, i: statistics.median(x[r][i] for r in rs)
    print("| %s | %s | %s | %s | %.1f -> %.1f | %.2f -> %.2f | %d | %d | %.2fx |" % (
        f, m, ", ".join("%.1f" % g[r][0] for r in rs), ", ".join("%.1f" % c[r][0] for r in rs),
        med(g, 1), med(c, 1), med(g, 2), med(c, 2), c[rs[0]][3], c[rs[0]][4], ratio))
PY
