# Sourced by the geomorphing benchmarks that measure flights against their sources
# (side_reach.sh, star_weight.sh, parents_weight.sh): the error meter's flags for each set,
# the first 12 s of a set's flyover as tilebench table1 cuts them, and a table of flights
# measured before and after. Sets $before (the caller's first argument, the binary before),
# $after (this tree's vkterrain) and $out (a folder removed on exit).
# The sets: out/puget.vkt (.ci/demo), /tmp/n48.vkt, /tmp/m4p.vkt with its raw source
# /tmp/m4.r16, and /tmp/p4k.vkt (the 4K Puget), built as bench/README.md says.
set -euo pipefail
before=$1
after=target/release/vkterrain
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
P="--measure-error sample/ps_height_1k.png --source-spacing 160 --source-vertical-scale 0.1"
N="--measure-error ../shared/data/srtm/N48W125.hgt"
M="--measure-error /tmp/m4.r16 --source-size 4097x4097 --source-spacing 90"
K="--measure-error ../shared/data/puget/ps_height_4k_8bit.jpg --source-spacing 40 --source-vertical-scale 25.7"
# start SET OUT.csv: the set's flyover keyframes up to 12 s.
start() {
  $after "$1" --headless --path flyover --frames 1 --size 64x48 --record "$out/keys.csv" > /dev/null 2>&1
  awk -F, 'NR == 1 || $1 <= 12' "$out/keys.csv" > "$2"
}
# outside_draws BINARY SET PATH TAU: the median GPU time outside the draws (the frame's copies,
# index builds and morph pass) over frames 5-59 of a 60-frame flight at 1024 x 768, and the
# median triangles.
outside_draws() {
  $1 "$2" --headless --path "$3" --frames 60 --size 1024x768 --tau "$4" --log "$out/g.csv" > /dev/null
  python3 - "$out/g.csv" <<'PY'
import csv, statistics, sys
r = list(csv.DictReader(open(sys.argv[1])))[5:]
print(f"{statistics.median(float(x['gpu_ms']) - float(x['gpu_draw_ms']) for x in r):.1f}",
      int(statistics.median(float(x['triangles']) for x in r)))
PY
}
# two_rounds SET PATH TAU: outside_draws for the binaries before and after, alternating, twice:
# sets ms_before and ms_after (the two rounds' ms, comma separated), tri_before and tri_after.
two_rounds() {
  ms_before="" ms_after="" tri_before="" tri_after=""
  local m t
  for round in 1 2; do
    read -r m tri_before < <(outside_draws "$before" "$@")
    ms_before="${ms_before:+$ms_before, }$m"
    read -r m tri_after < <(outside_draws "$after" "$@")
    ms_after="${ms_after:+$ms_after, }$m"
  done
}
# flown ARGS...: each binary, before then after, flies ARGS (with --log); sets m_before and
# m_after to its max_error_px, largest pop_px, frames popping over half a pixel, and median
# triangles.
flown() {
  local b r=()
  for b in "$before" "$after"; do
    $b "$@" --log "$out/f.csv" > /dev/null
    r+=("$(python3 - "$out/f.csv" <<'PY'
import csv, statistics, sys
r = list(csv.DictReader(open(sys.argv[1])))
pops = [float(x['pop_px']) for x in r[1:]]
print(max(float(x['max_error_px']) for x in r), max(pops), sum(p > 0.5 for p in pops),
      statistics.median(float(x['triangles']) for x in r))
PY
)")
  done
  m_before=${r[0]} m_after=${r[1]}
}
# flown_header, then flown_row NAME TAU ARGS... per flight: a table of flown's measures
# before and after, at --tau TAU, warm.
flown_header() {
  echo "| flight | tau | max_error_px before | after | pop_px before | after | frames over 0.5 px before | after | triangles (median) |"
  echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|"
}
flown_row() {
  local name=$1 tau=$2 e1 p1 n1 t1 e2 p2 n2 t2; shift 2
  flown "$@" --warmup --tau "$tau"
  read -r e1 p1 n1 t1 <<< "$m_before"
  read -r e2 p2 n2 t2 <<< "$m_after"
  printf '| %s | %s | %.3f | %.3f | %.3f | %.3f | %d | %d | %.0f |\n' \
    "$name" "$tau" "$e1" "$e2" "$p1" "$p2" "$n1" "$n2" "$t2"
  [ "$t1" = "$t2" ] || echo "(triangles before: $t1)"
}
