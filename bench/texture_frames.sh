#!/bin/bash
# Texture tiles in flight: frame time textured (--shading photo: the tile set's texture tiles)
# against untextured (--shading tint: no texture slots, the same file and geometry), at tau 1,
# and the texture bytes sent per flight against the geometry bytes. Cold flights (every tile
# and texture streams in), default budgets (1 GiB, 4 MB per frame, a quarter of the GPU budget
# for texture slots). Run from the repository root after `cargo build --release`.
set -euo pipefail
T=target/release/tiletool
V=target/release/vkterrain
D=../shared/data
out=${OUT:-/tmp/texture-frames}; mkdir -p $out
FRAMES=${FRAMES:-60}
[ -f $out/puget1k-photo.vkt ]  || $T build sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --texture sample/ps_texture_1k.png -o $out/puget1k-photo.vkt > /dev/null
[ -f $out/puget1k-relief.vkt ] || $T build sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 -o $out/puget1k-relief.vkt > /dev/null
[ -f $out/n48w125-relief.vkt ] || $T build $D/srtm/N48W125.hgt -o $out/n48w125-relief.vkt > /dev/null
echo "| tile set | path | shading | frame ms median | p99 | GPU draw ms median | geometry MB sent | texture MB sent | texture slots MB | tile-frames texture coarser |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for set in puget1k-photo puget1k-relief n48w125-relief; do
  for path in orbit flyover; do
    for shading in tint photo; do
      log=$out/$set-$path-$shading.csv
      $V $out/$set.vkt --headless --path $path --frames $FRAMES --size 1024x768 --tau 1 \
        --shading $shading --log $log > /dev/null
      python3 - "${log%.csv}.json" "$set" "$path" "$shading" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
g = s["gpu_draw_ms_median"]
print(f"| {sys.argv[2]} | {sys.argv[3]} | {sys.argv[4]} | {s['frame_ms_median']:.1f} | {s['frame_ms_p99']:.1f} | "
      f"{g:.1f} | {s['upload_mb']:.2f} | {s['upload_mb_textures']:.2f} | {s['texture_mb']:.2f} | {s['tiles_texture_coarser']} |")
PY
    done
  done
done
