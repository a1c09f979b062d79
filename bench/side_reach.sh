#!/usr/bin/env bash
# Over the side (issue 25, the error bound): the morph pass's star reaching across tile sides
# and taking each corner's segment up to the edge of the view, against a binary before it.
# Errors and pops (every frame measured against the source, warm) and triangles, then the
# morph pass's GPU time (time outside the draws), two rounds alternating.
# Usage: bench/side_reach.sh BEFORE_BINARY   (after cargo build --release; sets: out/puget.vkt,
#   /tmp/n48.vkt, /tmp/m4p.vkt with its raw source /tmp/m4.r16, as bench/README says)
source "$(dirname "$0")/measured_sets.sh"
start /tmp/n48.vkt "$out/n48.csv"
start /tmp/m4p.vkt "$out/m4.csv"
echo "| flight | tau | max_error_px before | after | pop_px before | after | triangles (median) before | after |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
row() { # name tau args...
  local name=$1 tau=$2; shift 2
  flown "$@" --tau "$tau" --upload-budget-mb 100000
  read -r e1 p1 _ t1 <<< "$m_before"
  read -r e2 p2 _ t2 <<< "$m_after"
  printf '| %s | %s | %.3f | %.3f | %.3f | %.3f | %.0f | %.0f |\n' \
    "$name" "$tau" "$e1" "$e2" "$p1" "$p2" "$t1" "$t2"
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
  two_rounds "$@"
  echo "| $(basename "$1") $2 | $3 | $ms_before | $ms_after | $tri_before | $tri_after |"
done
