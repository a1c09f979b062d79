#!/bin/bash
# When a pyramid's tiles are checked (`vkterrain --pyramid --checks`): on the frame that first
# needs them (`on-frame`, the default) or behind the frames with ancestors standing in
# (`behind`). Per set and mode: the time a process takes to open the set and draw one frame;
# a still camera at the flyover's first pose (40 frames): the frames until none is stood in
# for, and the frame time summed to it; the flyover's first 12 s at 30 frames a second (120
# frames, 0.1 s of path a frame) and the whole flyover in 60 frames (0.8 s a frame): median
# and largest frame, and the frames with tiles stood in for. 1024 x 768, file warm.
# Sets as bench/pyramid.sh makes them (GENERATED mirror sets of SRTM3 N55W003).
# usage: bench/checks.sh SET.vkt...
set -euo pipefail
V=target/release/vkterrain
out=${OUT:-/tmp/checks-bench}; mkdir -p "$out"
echo "| set | checks | to first frame | still: frames to the full view | still: ms to it | 30 fps: median, largest frame ms | 30 fps: frames standing in | 60 frames: median, largest ms | 60 frames: standing in |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|"
for vkt in "$@"; do
  name=$(basename "$vkt" .vkt)
  $V "$vkt" --headless --path flyover --frames 1 --size 64x48 --record "$out/$name.keys.csv" > /dev/null 2>&1
  python3 - "$out/$name" <<'PY'
import csv, sys
base = sys.argv[1]
rows = list(csv.reader(open(base + ".keys.csv")))
t = rows[0].index("time_s")
csv.writer(open(base + ".start.csv", "w")).writerows([rows[0]] + [r for r in rows[1:] if float(r[t]) <= 12])
still = rows[1][:]
still[t] = str(float(rows[1][t]) + 10)
csv.writer(open(base + ".still.csv", "w")).writerows([rows[0], rows[1], still])
PY
  for mode in on-frame behind; do
    run="$out/$name.$mode"
    # Discrete levels, as measured on 305e5bf (`--pyramid` geomorphs since e5b6866).
    f="--pyramid --no-geomorph --checks $mode --size 1024x768"
    /usr/bin/time -f "%e" -o "$run.first.time" $V "$vkt" --headless --frames 1 $f > /dev/null 2>&1
    $V "$vkt" --headless --path "$out/$name.still.csv" --frames 40 $f --log "$run.still.csv" > /dev/null
    $V "$vkt" --headless --path "$out/$name.start.csv" --frames 120 $f --log "$run.start.csv" > /dev/null
    $V "$vkt" --headless --path flyover --frames 60 $f --log "$run.fly.csv" > /dev/null
    python3 - "$run" "$name" "$mode" <<'PY'
import csv, statistics, sys
run, name, mode = sys.argv[1:]
col = lambda f, c: [float(r[c]) for r in csv.DictReader(open(f"{run}.{f}.csv"))]
first = float(open(f"{run}.first.time").read())
stood = col("still", "tiles_stood_in")
full = next((i for i, v in enumerate(stood) if v == 0), None)
to_full = "never" if full is None else f"{sum(col('still', 'frame_ms')[:full + 1]):.0f}"
def flight(f):
    ms = col(f, "frame_ms")
    return (f"{statistics.median(ms[5:]):.0f}, {max(ms):.0f}",
            f"{sum(1 for v in col(f, 'tiles_stood_in') if v > 0)} of {len(ms)}")
s, f = flight("start"), flight("fly")
print(f"| {name} | {mode} | {first:.2f} s | {full} | {to_full} | {s[0]} | {s[1]} | {f[0]} | {f[1]} |")
PY
  done
done
