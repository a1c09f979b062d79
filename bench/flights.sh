#!/bin/bash
# The geomorphing flight table in one run: the five flights of `tilebench limit` (Puget 1K
# orbit and flyover, SRTM1 N48W125 orbit and flyover, Puget 4K flyover), 60 frames at
# 1024x768, in brute force, discrete tau 1 and 3, geomorph tau 1, 2, 3, 5 and the
# forward-differences shader at tau 1. Prints the median frame (ms), triangles per frame and
# the GPU's draw time (ms) of each. No static-mesh limit: `tilebench limit` adds it (slower).
# Builds its tile sets into $SETS (default /tmp/flight-sets) the way `tilebench limit` does.
# Run from the repository root after `cargo build --release -p tiletool -p renderer`.
set -euo pipefail
V=target/release/vkterrain
T=target/release/tiletool
D=../shared/data
sets=${SETS:-/tmp/flight-sets}; mkdir -p "$sets"
[ -f "$sets/puget.vkt" ] || $T build $D/puget/ps_height_1k.png --spacing 160 --vertical-scale 0.1 -o "$sets/puget.vkt" --quiet --force
[ -f "$sets/n48.vkt" ] || $T build $D/srtm/N48W125.hgt -o "$sets/n48.vkt" --quiet --force
[ -f "$sets/p4k.vkt" ] || $T build $D/puget/ps_height_4k_8bit.jpg --spacing 40 --vertical-scale 25.7 -o "$sets/p4k.vkt" --quiet --force
log=$(mktemp -d)/flight.csv
echo "set path mode frame_ms_median triangles gpu_draw_ms_median"
for flight in "puget orbit" "puget flyover" "n48 orbit" "n48 flyover" "p4k flyover"; do
  set -- $flight
  for mode in "brute:--brute-force" "d1:--tau 1 --no-geomorph" "d3:--tau 3 --no-geomorph" \
      "g1:--tau 1" "g2:--tau 2" "g3:--tau 3" "g5:--tau 5" \
      "fd1:--tau 1 --morph-shader forward-differences"; do
    name=${mode%%:*}; args=${mode#*:}
    # shellcheck disable=SC2086
    $V "$sets/$1.vkt" --headless --path "$2" --frames 60 --size 1024x768 $args --log "$log" > /dev/null
    python3 -c "
import json; d = json.load(open('${log%.csv}.json'))
print('$1 $2 $name %.1f %d %.1f' % (d['frame_ms_median'], round(d['triangles_per_frame_mean']), d['gpu_draw_ms_median']))"
  done
done
