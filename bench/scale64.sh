#!/bin/bash
# The scale issue's 64K set, built coarse: what grows with the number of tiles (open, the
# first frame, the cut's CPU, resident memory), measured on GENERATED mirror tilings of the
# real SRTM3 tile N55W003 (bench/mirror.py) at 1025², 16385² and 65537² samples, each built
# with 2 levels and a 64 m base error so that a 4.3 G-sample set builds in half an hour here:
#   python3 bench/mirror.py ../shared/data/srtm/N55W003.hgt 65537 m64.r16     # 8.6 GB, 31 s
#   target/release/tiletool build m64.r16 --size 65537x65537 --spacing 90 --levels 2 \
#       --base-error 64 --pyramid --compact --no-texture -o m64l2.vkt           # 29.5 min
# (likewise 1025 and 16385). For each set: three processes that open it and draw one frame
# (orbit), then the orbit and the flyover, 60 frames at 1024 x 768 through the pyramid
# (`--pyramid`, tau 1, geomorphing), medians after frame 5.
# usage: bench/scale64.sh SET.vkt...     (run from the repository root after cargo build --release;
#        V=path/to/vkterrain for another binary)
set -euo pipefail
V=${V:-target/release/vkterrain}
out=${OUT:-/tmp/scale64}; mkdir -p "$out"
for vkt in "$@"; do
  name=$(basename "$vkt" .vkt)
  for i in 1 2 3; do
    /usr/bin/time -f "%e %M" -o "$out/$name.first$i.time" $V "$vkt" --headless --pyramid --path orbit --frames 1 --size 1024x768 > "$out/$name.first$i.json" 2>/dev/null
  done
  for path in orbit flyover; do
    /usr/bin/time -f "%e %M" -o "$out/$name.$path.time" $V "$vkt" --headless --pyramid --path $path --frames 60 --size 1024x768 --log "$out/$name.$path.csv" > "$out/$name.$path.json" 2>/dev/null
  done
  python3 - "$out" "$name" <<'PY'
import csv, json, statistics, sys
out, name = sys.argv[1:]
firsts = []
for i in (1, 2, 3):
    j = json.load(open(f"{out}/{name}.first{i}.json"))
    wall, kb = open(f"{out}/{name}.first{i}.time").read().split()
    firsts.append((float(wall), j["open_ms"], j["first_view_check_ms"]))
print(name, "first frame s", [f[0] for f in firsts], "open ms", [round(f[1], 1) for f in firsts], "first view checks ms", [round(f[2]) for f in firsts])
for path in ("orbit", "flyover"):
    j = json.load(open(f"{out}/{name}.{path}.json"))
    wall, kb = open(f"{out}/{name}.{path}.time").read().split()
    rows = list(csv.DictReader(open(f"{out}/{name}.{path}.csv")))[5:]
    med = lambda f: statistics.median(f(r) for r in rows)
    col = lambda c: (lambda r: float(r[c] or 0))
    cpu = lambda r: sum(float(r[c] or 0) for c in ("cpu_cull_ms", "cpu_lod_ms", "cpu_residency_ms", "cpu_stitch_ms", "cpu_record_ms"))
    print(name, path, "frame ms", round(med(col("frame_ms")), 1), "CPU ms", round(med(cpu), 2), "max CPU ms", round(max(cpu(r) for r in rows), 2),
          "checks ms", round(med(col("cpu_check_ms")), 1), "tiles", med(col("tiles_drawn")), "max tiles", max(col("tiles_drawn")(r) for r in rows),
          "tris", j["triangles_per_frame_mean"], "RSS MB", round(int(kb) / 1024), "validation", j["validation_messages"], "failed", j["tiles_failed"])
PY
done
