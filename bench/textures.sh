#!/bin/bash
# Texture tiles: preprocessing throughput and BC1 PSNR per mip (tiletool's own summary, one
# build each), and what the textures add to a tile set. Run from the repository root after
# `cargo build --release`. Thread time is summed over tiletool's workers, so "per core" is
# source texels divided by thread-seconds spent on textures (decode of the photo excluded).
set -euo pipefail
T=target/release/tiletool
D=../shared/data
out=${OUT:-/tmp/texture-bench}; mkdir -p $out
build() { name=$1; shift; /usr/bin/time -f "%e s wall, %M KB peak" $T build "$@" -o $out/$name.vkt --force > $out/$name.txt 2> $out/$name.time; }
build puget1k-none   sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --no-texture
build puget1k-photo  sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --texture sample/ps_texture_1k.png
build puget1k-relief sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1
build puget1k-tint   sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --tint
build puget1k-photo4x sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --texture sample/ps_texture_1k.png --texels-per-sample 4
build puget4k-relief $D/puget/ps_height_4k_8bit.jpg --spacing 40 --vertical-scale 25.7
build n48w125-none   $D/srtm/N48W125.hgt --no-texture
build n48w125-relief $D/srtm/N48W125.hgt
echo "| build | texture | layer (mips) | texture s (thread) | M source (tile) texels/min/core | PSNR per mip, finest first (dB) | file MB | wall s |"
echo "|---|---|---|---|---|---|---|---|"
for f in $out/*.txt; do
  name=$(basename $f .txt)
  python3 - "$f" "$out/$name.time" "$name" <<'PY'
import re, sys
txt = open(sys.argv[1]).read(); tm = open(sys.argv[2]).read(); name = sys.argv[3]
wall = re.search(r"([\d.]+) s wall", tm).group(1)
mb = re.search(r"file\s+([\d.]+) MB", txt).group(1)
m = re.search(r"texture\s+(.*)", txt)
if not m:
    print(f"| {name} | none | | | | | {mb} | {wall} |"); sys.exit()
kind = m.group(1).split(",")[0]
lay = re.search(r"= (\d+) per layer, (\d+) mips", txt)
psnr = re.findall(r"^\s+\d+\s+\d+x\d+\s+([\d.]+)\s+\d+$", txt, re.M)
thr = re.search(r"([\d.]+) s of thread time: (\d+) M source texels", txt)
made = re.search(r"\((\d+) M tile texels made\)", txt).group(1)
print(f"| {name} | {kind} | {lay.group(1)} ({lay.group(2)}) | {thr.group(1)} | {thr.group(2)} ({made}) | {' '.join(psnr)} | {mb} | {wall} |")
PY
done
