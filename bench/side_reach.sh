#!/usr/bin/env bash
# Over the side (issue 25, the error bound): the morph pass's star reaching across tile sides
# and taking each corner's segment up to the edge of the view, against a binary before it.
# Errors and pops (every frame measured against the source, warm) and triangles, then the
# morph pass's GPU time (time outside the draws), two rounds alternating.
# Usage: bench/side_reach.sh BEFORE_BINARY   (after cargo build --release; sets: out/puget.vkt,
#   /tmp/n48.vkt, /tmp/m4p.vkt with its raw source /tmp/m4.r16, as bench/README says)
set -euo pipefail
before=$1
after=target/release/vkterrain
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
P="--measure-error sample/ps_height_1k.png --source-spacing 160 --source-vertical-scale 0.1"
N="--measure-error ../shared/data/srtm/N48W125.hgt"
M="--measure-error /tmp/m4.r16 --source-size 4097x4097 --source-spacing 90"
# The flyovers' first 12 s at 30 frames a second, as tilebench table1 cuts them.
start() {
  $after "$1" --headless --path flyover --frames 1 --size 64x48 --record "$out/keys.csv" > /dev/null 2>&1
  python3 - "$out/keys.csv" "$2" <<'PY'
import csv, sys
rows = list(csv.reader(open(sys.argv[1])))
t = rows[0].index("time_s")
csv.writer(open(sys.argv[2], "w")).writerows([rows[0]] + [r for r in rows[1:] if float(r[t]) <= 12])
PY
}
start /tmp/n48.vkt "$out/n48.csv"
start /tmp/m4p.vkt "$out/m4.csv"
echo "| flight | tau | max_error_px before | after | pop_px before | after | triangles (median) before | after |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
row() { # name tau args...
  local name=$1 tau=$2; shift 2
  local r=()
  for b in "$before" "$after"; do
    $b "$@" --tau "$tau" --upload-budget-mb 100000 --log "$out/f.csv" > /dev/null
    r+=("$(python3 -c "
import csv, statistics
r = list(csv.DictReader(open('$out/f.csv')))
print(max(float(x['max_error_px']) for x in r), max(float(x['pop_px']) for x in r[1:]), statistics.median(float(x['triangles']) for x in r))")")
  done
  python3 -c "
a, b = '${r[0]}'.split(), '${r[1]}'.split()
print(f'| $name | $tau | {float(a[0]):.3f} | {float(b[0]):.3f} | {float(a[1]):.3f} | {float(b[1]):.3f} | {float(a[2]):.0f} | {float(b[2]):.0f} |')"
}
for tau in 1 3 5; do
  row "Puget flyover, 120 frames, 1024 x 768" $tau out/puget.vkt --headless --path flyover --frames 120 --size 1024x768 $P
done
row "Puget orbit, 120 frames, 1024 x 768" 3 out/puget.vkt --headless --path orbit --frames 120 --size 1024x768 $P
row "N48W125 orbit, 120 frames, 1024 x 768" 3 /tmp/n48.vkt --headless --path orbit --frames 120 --size 1024x768 $N
for tau in 3 5; do
  row "N48W125 flyover, first 12 s at 30 frames a second, 480 x 360" $tau /tmp/n48.vkt --headless --path "$out/n48.csv" --frames 360 --size 480x360 $N
done
for tau in 1 3; do
  row "4K mirror (GENERATED) flyover, first 12 s at 30 frames a second, 480 x 360" $tau /tmp/m4p.vkt --headless --path "$out/m4.csv" --frames 120 --size 480x360 $M
done
echo
echo "| flight | tau | before: outside the draws, ms (two rounds) | after | triangles before | after |"
echo "|---|---:|---|---|---:|---:|"
for spec in "out/puget.vkt orbit 1" "out/puget.vkt flyover 1" "/tmp/n48.vkt orbit 1" "out/puget.vkt flyover 3"; do
  set -- $spec
  declare -A ms=() tri=()
  for round in 1 2; do
    for b in before after; do
      bin=$before; [ $b = after ] && bin=$after
      $bin "$1" --headless --path "$2" --frames 60 --size 1024x768 --tau "$3" --log "$out/g.csv" > /dev/null
      read -r m t < <(python3 -c "
import csv, statistics
r = list(csv.DictReader(open('$out/g.csv')))[5:]
print(f\"{statistics.median(float(x['gpu_ms']) - float(x['gpu_draw_ms']) for x in r):.1f}\", int(statistics.median(float(x['triangles']) for x in r)))")
      ms[$b]="${ms[$b]:+${ms[$b]}, }$m"; tri[$b]=$t
    done
  done
  echo "| $(basename "$1") $2 | $3 | ${ms[before]} | ${ms[after]} | ${tri[before]} | ${tri[after]} |"
  unset ms tri
done
