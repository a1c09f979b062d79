#!/bin/bash
# The paper's Table 1 on our data: the Puget 1K flyover (the README's demo tile set,
# out/puget.vkt), warm, 40 frames at 480x360, every frame measured against the source.
# Run from the repository root after `cargo build --release`.
set -euo pipefail
V=target/release/vkterrain
PF="--measure-error ../shared/data/puget/ps_height_1k.png --source-spacing 160 --source-vertical-scale 0.1"
out=${OUT:-/tmp/geomorph-bench}; mkdir -p $out
run() { name=$1; shift; $V "$@" --headless --frames 40 --size 480x360 --warmup 2>/dev/null > $out/$name.json; python3 -c "
import json,sys; s=json.load(open('$out/$name.json'))
print('%-28s %8.1f %10.0f %6.2f %6.2f' % ('$name', s['frame_ms_median'], s['triangles_per_frame_mean'], s['max_error_px'] or -1, s['pop_px'] or -1))"; }
echo "name frame_ms_median triangles max_error_px pop_px"
for p in flyover; do
  run puget-$p-tau1-discrete out/puget.vkt --path $p --tau 1 --no-geomorph $PF
  for t in 1 2 3 5; do run puget-$p-tau$t-morph out/puget.vkt --path $p --tau $t $PF; done
  run puget-$p-tau1-morph-all-rows out/puget.vkt --path $p --tau 1 --morph-shader forward-differences $PF
done
