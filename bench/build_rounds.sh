#!/bin/bash
# Build throughput of two tiletool binaries, alternating within each round (this machine's
# speed moves from minute to minute): per input, each binary builds the same set ROUNDS times
# (default 2), and the table gives the median wall and CPU time, samples a minute at the
# median, peak memory, and whether the two binaries' sets are the same bytes.
# Inputs: the demo's Puget 1K with its photo, SRTM1 N48W125 with the default relief texture,
# and the GENERATED 4K mirror of N55W003 without texture (bench/mirror.py; meshing alone):
#   python3 bench/mirror.py ../shared/data/srtm/N55W003.hgt 4097 m4.r16
# usage: bench/build_rounds.sh BEFORE/tiletool AFTER/tiletool M4.r16
set -euo pipefail
before=$1 after=$2 m4=$3
rounds=${ROUNDS:-2}
out=${OUT:-/tmp/build-rounds}; mkdir -p "$out"
data=${DATA:-../shared/data}
inputs=(
  "puget|1050625|sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --texture sample/ps_texture_1k.png"
  "n48w125|12967201|$data/srtm/N48W125.hgt"
  "mirror4k|16785409|$m4 --size 4097x4097 --spacing 90 --no-texture"
)
echo "| input | binary | wall s (rounds) | CPU s (rounds) | M samples/min | peak MB | same bytes |"
echo "|---|---|---|---|---:|---:|---|"
for spec in "${inputs[@]}"; do
  IFS='|' read -r name samples args <<< "$spec"
  for r in $(seq "$rounds"); do
    for b in before after; do
      bin=$before; [ $b = after ] && bin=$after
      # shellcheck disable=SC2086
      /usr/bin/time -f "%e %U %S %M" -o "$out/$name.$b.$r.time" \
        "$bin" build $args -o "$out/$name.$b.vkt" --quiet --force
    done
  done
  same=$(cmp -s "$out/$name.before.vkt" "$out/$name.after.vkt" && echo yes || echo NO)
  for b in before after; do
    python3 - "$out" "$name" "$b" "$rounds" "$samples" "$same" <<'PY'
import statistics, sys
out, name, b, rounds, samples, same = sys.argv[1:]
runs = [open(f"{out}/{name}.{b}.{r}.time").read().split() for r in range(1, int(rounds) + 1)]
wall = [float(r[0]) for r in runs]
cpu = [float(r[1]) + float(r[2]) for r in runs]
peak = max(int(r[3]) for r in runs) / 1024
rate = int(samples) / 1e6 / (statistics.median(wall) / 60)
fmt = lambda v: f"{statistics.median(v):.2f} ({', '.join(f'{x:.2f}' for x in v)})"
print(f"| {name} | {b} | {fmt(wall)} | {fmt(cpu)} | {rate:.0f} | {peak:.0f} | {same} |")
PY
  done
done
