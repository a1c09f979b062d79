#!/usr/bin/env bash
# A vertex at its parents' weight within its block (issue 25, the error over tau on the 4K
# Puget), against a binary before it: errors, pops and triangles on flights measured warm
# against the source on every frame (the whole 4K Puget flyover in 120 frames at 1024 x 768,
# where 1.008 px was measured at tau 1, and the flyovers' first 12 s at 30 frames a second, as
# tilebench table1 cuts them), then the morph pass's GPU time (time outside the draws), two
# rounds alternating.
# Usage: bench/parents_weight.sh BEFORE_BINARY   (after cargo build --release -p renderer;
#   sets: out/puget.vkt (.ci/demo), /tmp/n48.vkt and /tmp/p4k.vkt, built as bench/README.md
#   says)
source "$(dirname "$0")/measured_sets.sh"
start out/puget.vkt "$out/puget.csv"
start /tmp/n48.vkt "$out/n48.csv"
start /tmp/p4k.vkt "$out/p4k.csv"
flown_header
for tau in 1 3; do
  flown_row "4K Puget flyover, 120 frames, 1024 x 768" $tau /tmp/p4k.vkt --headless --path flyover --frames 120 --size 1024x768 $K
done
for tau in 3 5; do
  flown_row "4K Puget flyover, first 12 s, 360 frames, 480 x 360" $tau /tmp/p4k.vkt --headless --path "$out/p4k.csv" --frames 360 --size 480x360 $K
done
flown_row "Puget flyover, first 12 s, 360 frames, 480 x 360" 5 out/puget.vkt --headless --path "$out/puget.csv" --frames 360 --size 480x360 $P
flown_row "N48W125 flyover, first 12 s, 360 frames, 480 x 360" 5 /tmp/n48.vkt --headless --path "$out/n48.csv" --frames 360 --size 480x360 $N
echo
echo "| flight | tau | before: outside the draws, ms (two rounds) | after |"
echo "|---|---:|---|---|"
for spec in "out/puget.vkt orbit 1" "/tmp/p4k.vkt flyover 1" "/tmp/n48.vkt orbit 1"; do
  set -- $spec
  two_rounds "$@"
  echo "| $(basename "$1") $2 | $3 | $ms_before | $ms_after |"
done
