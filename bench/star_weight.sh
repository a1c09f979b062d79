#!/usr/bin/env bash
# A star's weight from how deep its segment reaches in view (issue 25, pops at tau 5), against
# a binary before it: errors, pops and triangles on flights measured warm against the source on
# every frame (the flyovers' first 12 s at 30 frames a second, as tilebench table1 cuts them,
# and the whole Puget flyover in 120 frames), then the morph pass's GPU time (time outside the
# draws), two rounds alternating.
# Usage: bench/star_weight.sh BEFORE_BINARY   (after cargo build --release -p renderer; sets:
#   out/puget.vkt (.ci/demo), /tmp/n48.vkt and /tmp/m4p.vkt with its raw source /tmp/m4.r16,
#   built as bench/README.md says)
set -euo pipefail
before=$1
after=target/release/vkterrain
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
P="--measure-error sample/ps_height_1k.png --source-spacing 160 --source-vertical-scale 0.1"
N="--measure-error ../shared/data/srtm/N48W125.hgt"
M="--measure-error /tmp/m4.r16 --source-size 4097x4097 --source-spacing 90"
# The first 12 s of a set's flyover: its recorded keyframes up to 12 s.
start() {
  $after "$1" --headless --path flyover --frames 1 --size 64x48 --record "$out/keys.csv" > /dev/null 2>&1
  awk -F, 'NR == 1 || $1 <= 12' "$out/keys.csv" > "$2"
}
start out/puget.vkt "$out/puget.csv"
start /tmp/n48.vkt "$out/n48.csv"
start /tmp/m4p.vkt "$out/m4.csv"
# max_error_px, the largest pop_px, the frames popping over half a pixel, median triangles.
measures() {
  python3 - "$1" <<'PY'
import csv, statistics, sys
r = list(csv.DictReader(open(sys.argv[1])))
pops = [float(x['pop_px']) for x in r[1:]]
print(max(float(x['max_error_px']) for x in r), max(pops), sum(p > 0.5 for p in pops),
      statistics.median(float(x['triangles']) for x in r))
PY
}
echo "| flight | tau | max_error_px before | after | pop_px before | after | frames over 0.5 px before | after | triangles (median) |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|"
row() { # name tau args...
  local name=$1 tau=$2; shift 2
  local r=()
  for b in "$before" "$after"; do
    $b "$@" --warmup --tau "$tau" --log "$out/f.csv" > /dev/null
    r+=("$(measures "$out/f.csv")")
  done
  read -r e1 p1 n1 t1 <<< "${r[0]}"
  read -r e2 p2 n2 t2 <<< "${r[1]}"
  printf '| %s | %s | %.3f | %.3f | %.3f | %.3f | %d | %d | %.0f |\n' \
    "$name" "$tau" "$e1" "$e2" "$p1" "$p2" "$n1" "$n2" "$t2"
  [ "$t1" = "$t2" ] || echo "(triangles before: $t1)"
}
for tau in 1 3 5; do
  row "Puget flyover, first 12 s, 360 frames, 480 x 360" $tau out/puget.vkt --headless --path "$out/puget.csv" --frames 360 --size 480x360 $P
done
for tau in 3 5; do
  row "N48W125 flyover, first 12 s, 360 frames, 480 x 360" $tau /tmp/n48.vkt --headless --path "$out/n48.csv" --frames 360 --size 480x360 $N
done
for tau in 1 3; do
  row "4K mirror (GENERATED) flyover, first 12 s, 360 frames, 480 x 360" $tau /tmp/m4p.vkt --headless --path "$out/m4.csv" --frames 360 --size 480x360 $M
done
for tau in 3 5; do
  row "Puget flyover, 120 frames, 1024 x 768" $tau out/puget.vkt --headless --path flyover --frames 120 --size 1024x768 $P
done
echo
echo "| flight | tau | before: outside the draws, ms (two rounds) | after |"
echo "|---|---:|---|---|"
for spec in "out/puget.vkt orbit 1" "out/puget.vkt flyover 3" "/tmp/n48.vkt orbit 1"; do
  set -- $spec
  declare -A ms=()
  for round in 1 2; do
    for b in before after; do
      bin=$before; [ $b = after ] && bin=$after
      $bin "$1" --headless --path "$2" --frames 60 --size 1024x768 --tau "$3" --log "$out/g.csv" > /dev/null
      m=$(python3 -c "
import csv, statistics
r = list(csv.DictReader(open('$out/g.csv')))[5:]
print(f\"{statistics.median(float(x['gpu_ms']) - float(x['gpu_draw_ms']) for x in r):.1f}\")")
      ms[$b]="${ms[$b]:+${ms[$b]}, }$m"
    done
  done
  echo "| $(basename "$1") $2 | $3 | ${ms[before]} | ${ms[after]} |"
  unset ms
done
