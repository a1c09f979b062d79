#!/bin/bash
# Scale: opening and flying sets of 1K to 16K samples a side. The sets above the Puget 1K
# are GENERATED: mirror tilings of the real SRTM3 tile N55W003 (bench/mirror.py), made here
# and kept out of the repository (about 3.5 GB for the 16K set, under $OUT).
# Run from the repository root after `cargo build --release`.
# usage: bench/scale.sh [SIZES]   (default: 4097 16385)
set -euo pipefail
V=target/release/vkterrain
T=target/release/tiletool
out=${OUT:-/tmp/scale-bench}; mkdir -p "$out"
sizes=${1:-"4097 16385"}
src=../shared/data/srtm/N55W003.hgt

# One set: build it (timed, peak memory), then open it and fly.
bench() {
  name=$1 vkt=$2
  # Open to first frame, twice: a cold page cache (the set dropped first), then warm.
  for cache in cold warm; do
    extra=""
    if [ $cache = cold ]; then
      # Out of the page cache before the process starts (clean pages: the kernel drops them),
      # and again after opening, so that the first view's checks read from disk too.
      python3 -c 'import os,sys; f=os.open(sys.argv[1],os.O_RDONLY); os.posix_fadvise(f,0,0,os.POSIX_FADV_DONTNEED)' "$vkt"
      extra="--cold-file-cache"
    fi
    /usr/bin/time -f "%e %M" -o "$out/$name.$cache.time" \
      $V "$vkt" --headless --frames 1 --size 1024x768 $extra > "$out/$name.$cache.json" 2>/dev/null
  done
  # The flyover: 30 frames, per-frame CPU and the resident set.
  /usr/bin/time -f "%e %M" -o "$out/$name.fly.time" \
    $V "$vkt" --headless --frames 30 --size 1024x768 --log "$out/$name.fly.csv" > "$out/$name.fly.json" 2>/dev/null
  python3 - "$out" "$name" "$vkt" <<'PY'
import json, os, sys
out, name, vkt = sys.argv[1:]
def t(kind):
    wall, kb = open(f"{out}/{name}.{kind}.time").read().split()
    return float(wall), int(kb) / 1024
def j(kind):
    return json.load(open(f"{out}/{name}.{kind}.json"))
cold, warm, fly = j("cold"), j("warm"), j("fly")
rows = [l.split(",") for l in open(f"{out}/{name}.fly.csv").read().splitlines()]
head = rows[0]
col = lambda c: [float(r[head.index(c)] or 0) for r in rows[1:]]
visible = col("tiles_visible")
size = os.path.getsize(vkt)
print(f"{name:>10} | {size/1e9:6.2f} GB | open {warm['open_ms']:7.1f} ms (cold {cold['open_ms']:7.1f}) | "
      f"first view check {warm['first_view_check_ms']:7.0f} ms | "
      f"to first frame {t('warm')[0]:5.1f} s (cold {t('cold')[0]:5.1f} s) | "
      f"flight: tiles visible median {sorted(visible)[len(visible)//2]:.0f}, "
      f"cpu_ms median {fly['cpu_ms_median']:.1f}, checked in frames {fly['tiles_checked_in_frames']}, "
      f"peak RSS {t('fly')[1]:.0f} MB, mapped at end {fly['file_mapped_mb_end'] or 0:.0f} MB")
PY
}

echo "set | file | open | first view check | to first frame | flight"
# The Puget 1K (real data), as the demo builds it.
[ -f out/puget.vkt ] || { mkdir -p out; $T build sample/ps_height_1k.png --spacing 160 \
  --vertical-scale 0.1 --texture sample/ps_texture_1k.png -o out/puget.vkt --quiet; }
bench puget-1k out/puget.vkt
for n in $sizes; do
  vkt="$out/mirror-$n.vkt"
  if [ ! -f "$vkt" ]; then
    python3 bench/mirror.py "$src" "$n" "$out/mirror-$n.r16"
    /usr/bin/time -f "%e s, peak %M KB" -o "$out/mirror-$n.build.time" \
      $T build "$out/mirror-$n.r16" --size ${n}x${n} --spacing 90 -o "$vkt" --quiet
    rm -f "$out/mirror-$n.r16"
    echo "mirror-$n build: $(cat "$out/mirror-$n.build.time")"
  fi
  bench "mirror-$n" "$vkt"
done
