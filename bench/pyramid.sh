#!/bin/bash
# The tile pyramid in flight: each set drawn as its base grid (discrete levels, tau 1) and as
# a cut through its pyramid (`vkterrain --pyramid`), on the orbit and the flyover, 60 frames
# at 1024 x 768, modes alternating within each flight. Per run: the time to the first frame
# (a process that opens the set and draws one frame, file warm in the page cache), the first
# view's checks, and over the flight the medians (after frame 5) of the frame, the CPU's
# decisions (cull or cut, LOD, residency, stitching, recording), the checks of tiles first
# needed, tiles drawn (of them from the layers above the base), triangles, and the peak
# resident set. A third flight: the flyover's first 12 s at 30 frames a second (360 frames).
# Sets must be built with `tiletool build --pyramid`; the mirror sets are GENERATED
# (bench/mirror.py of the real SRTM3 tile N55W003), e.g.
#   python3 bench/mirror.py ../shared/data/srtm/N55W003.hgt 16385 m16.r16
#   target/release/tiletool build m16.r16 --size 16385x16385 --spacing 90 --pyramid -o m16p.vkt
# Run from the repository root after `cargo build --release`.
# usage: bench/pyramid.sh SET.vkt...
set -euo pipefail
V=target/release/vkterrain
out=${OUT:-/tmp/pyramid-bench}; mkdir -p "$out"
echo "| set | flight | drawn as | to first frame | first view checked | frame ms | CPU ms | checks ms | tiles drawn (above base) | triangles | peak RSS |"
echo "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"
for vkt in "$@"; do
  name=$(basename "$vkt" .vkt)
  # The flyover's first 12 s at 30 frames a second (the other flights move 0.4-0.8 s of path
  # a frame): its keyframes up to 12 s, as `tilebench table1` takes them.
  $V "$vkt" --headless --path flyover --frames 1 --size 64x48 --record "$out/$name.keys.csv" > /dev/null 2>&1
  python3 - "$out/$name.keys.csv" "$out/$name.start.csv" <<'PY'
import csv, sys
rows = list(csv.reader(open(sys.argv[1])))
t = rows[0].index("time_s")
csv.writer(open(sys.argv[2], "w")).writerows([rows[0]] + [r for r in rows[1:] if float(r[t]) <= 12])
PY
  for path in orbit flyover start; do
    frames=60
    where=$path
    [ $path = start ] && { frames=360; where="$out/$name.start.csv"; }
    for mode in base pyramid; do
      flags="--no-geomorph"
      # Discrete levels both ways, as measured on 0b007a6 (`--pyramid` geomorphs since e5b6866).
      [ $mode = pyramid ] && flags="--pyramid --no-geomorph"
      run="$out/$name.$path.$mode"
      /usr/bin/time -f "%e %M" -o "$run.first.time" \
        $V "$vkt" --headless --path $where --frames 1 --size 1024x768 $flags > "$run.first.json" 2>/dev/null
      /usr/bin/time -f "%e %M" -o "$run.fly.time" \
        $V "$vkt" --headless --path $where --frames $frames --size 1024x768 $flags \
        --log "$run.fly.csv" > "$run.fly.json" 2>/dev/null
      python3 - "$run" "$name" "$path" "$mode" <<'PY'
import csv, json, statistics, sys
run, name, path, mode = sys.argv[1:]
first = json.load(open(f"{run}.first.json"))
wall, _ = open(f"{run}.first.time").read().split()
_, kb = open(f"{run}.fly.time").read().split()
rows = list(csv.DictReader(open(f"{run}.fly.csv")))[5:]
med = lambda f: statistics.median(f(r) for r in rows)
col = lambda c: (lambda r: float(r[c] or 0))
cpu = lambda r: sum(float(r[c] or 0) for c in
                    ("cpu_cull_ms", "cpu_lod_ms", "cpu_residency_ms", "cpu_stitch_ms", "cpu_record_ms"))
path = {"start": "flyover, first 12 s at 30 frames a second"}.get(path, path)
print(f"| {name} | {path} | {'cut through the pyramid' if mode == 'pyramid' else 'base grid'} "
      f"| {float(wall):.2f} s | {first['first_view_check_ms']:.0f} ms "
      f"| {med(col('frame_ms')):.1f} | {med(cpu):.2f} | {med(col('cpu_check_ms')):.1f} "
      f"| {med(col('tiles_drawn')):.0f} ({med(col('tiles_above_base')):.0f}) "
      f"| {med(col('triangles')):.0f} | {int(kb) / 1024:.0f} MB |")
PY
    done
  done
done
