#!/usr/bin/env bash
# A star's weight from how deep its segment reaches in view (issue 25, pops at tau 5), against
# a binary before it: errors, pops and triangles on flights measured warm against the source on
# every frame (the flyovers' first 12 s at 30 frames a second, as tilebench table1 cuts them,
# and the whole Puget flyover in 120 frames), then the morph pass's GPU time (time outside the
# draws), two rounds alternating.
# Usage: bench/star_weight.sh BEFORE_BINARY   (after cargo build --release -p renderer; sets:
#   out/puget.vkt (.ci/demo), /tmp/n48.vkt and /tmp/m4p.vkt with its raw source /tmp/m4.r16,
#   built as bench/README.md says)
source "$(dirname "$0")/measured_sets.sh"
start out/puget.vkt "$out/puget.csv"
start /tmp/n48.vkt "$out/n48.csv"
start /tmp/m4p.vkt "$out/m4.csv"
flown_header
for tau in 1 3 5; do
  flown_row "Puget flyover, first 12 s, 360 frames, 480 x 360" $tau out/puget.vkt --headless --path "$out/puget.csv" --frames 360 --size 480x360 $P
done
for tau in 3 5; do
  flown_row "N48W125 flyover, first 12 s, 360 frames, 480 x 360" $tau /tmp/n48.vkt --headless --path "$out/n48.csv" --frames 360 --size 480x360 $N
done
for tau in 1 3; do
  flown_row "4K mirror (GENERATED) flyover, first 12 s, 360 frames, 480 x 360" $tau /tmp/m4p.vkt --headless --path "$out/m4.csv" --frames 360 --size 480x360 $M
done
for tau in 3 5; do
  flown_row "Puget flyover, 120 frames, 1024 x 768" $tau out/puget.vkt --headless --path flyover --frames 120 --size 1024x768 $P
done
echo
echo "| flight | tau | before: outside the draws, ms (two rounds) | after |"
echo "|---|---:|---|---|"
for spec in "out/puget.vkt orbit 1" "out/puget.vkt flyover 3" "/tmp/n48.vkt orbit 1"; do
  set -- $spec
  two_rounds "$@"
  echo "| $(basename "$1") $2 | $3 | $ms_before | $ms_after |"
done
