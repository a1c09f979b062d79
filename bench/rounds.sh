#!/bin/bash
# Issue 25's frame goals in rounds: discrete tau 1, geomorph tau 1 and 3 (the device's
# default otherwise) and brute force, alternated within each round so that the machine's
# drift (up to 1.4x within minutes on lavapipe) falls on every mode alike. Each ratio is taken
# within its round, then the median over rounds is printed. Flights: the Puget 1K flyover and
# orbit (the demo's out/puget.vkt) and the SRTM N48W125 flyover and orbit (built here with
# the default options, as bench/device.sh builds it), 60 frames at 1024x768, the median frame
# after frame 5. Then the static-mesh limit (`--static-grid`) at each mode's triangles.
#
#   cargo build --release -p tiletool -p renderer && bash .ci/demo   # out/puget.vkt
#   bench/rounds.sh [ROUNDS]                                          # default 3, ~3.5 min each
set -euo pipefail
rounds=${1:-3}
# shellcheck source=bench/issue25_sets.sh
source "$(dirname "$0")/issue25_sets.sh" /tmp/rounds-bench
rows=$out/rows.txt; : > "$rows"
for round in $(seq "$rounds"); do
  for flight in "${flights[@]}"; do
    set -- $flight
    for mode in "${modes[@]}"; do
      # shellcheck disable=SC2086
      fly "$1" "$2" $mode
      python3 - "$round" "$(basename "$1" .vkt) $2" "$mode" "$out/log.csv" >> "$rows" <<'PY'
import csv, sys
r = list(csv.DictReader(open(sys.argv[4])))[5:]
med = lambda f: sorted(f(x) for x in r)[len(r) // 2]
print("|".join(sys.argv[1:4] + [
    "%.2f" % med(lambda x: float(x["frame_ms"])),
    "%.2f" % med(lambda x: float(x["gpu_draw_ms"])),
    "%.2f" % med(lambda x: float(x["gpu_ms"]) - float(x["gpu_draw_ms"])),
    "%d" % med(lambda x: int(x["triangles"]) + int(x["stitch_triangles"])),
]))
PY
    done
  done
done
python3 - "$rows" "$B/vkterrain" "$N" <<'PY'
import collections, json, statistics, subprocess, sys
rows = [l.rstrip("\n").split("|") for l in open(sys.argv[1])]
runs = collections.defaultdict(dict)
for rnd, flight, mode, frame, draw, outside, tris in rows:
    runs[(flight, mode)][int(rnd)] = (float(frame), float(draw), float(outside), int(tris))
flights = list(dict.fromkeys(f for f, _ in runs))
modes = list(dict.fromkeys(m for _, m in runs))
def limit(tris):
    s = subprocess.run([sys.argv[2], sys.argv[3], "--headless", "--static-grid", str(tris),
                        "--frames", "40", "--size", "1024x768"], capture_output=True, check=True)
    return json.loads(s.stdout)["frame_ms_median"]
print("| flight | mode | frame ms, each round | outside the draws, ms | triangles | frame / discrete tau 1 (median of rounds) | brute force / this | limit ms | frame / limit |")
print("|---|---|---|---|---:|---:|---:|---:|---:|")
for f in flights:
    base, brute = runs[(f, modes[0])], runs[(f, modes[-1])]
    for m in modes:
        x = runs[(f, m)]
        rs = sorted(x)
        ratio = statistics.median(x[r][0] / base[r][0] for r in rs)
        vs_brute = statistics.median(brute[r][0] / x[r][0] for r in rs)
        tris = x[rs[0]][3]
        lim = limit(tris)
        frame = statistics.median(x[r][0] for r in rs)
        print(f"| {f} | {m} | {', '.join('%.1f' % x[r][0] for r in rs)} | "
              f"{', '.join('%.1f' % x[r][2] for r in rs)} | {tris} | {ratio:.2f}x | "
              f"{vs_brute:.2f}x | {lim:.1f} | {frame / lim:.1f}x |")
PY
