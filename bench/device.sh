#!/bin/bash
# The flight table on a lent GPU (the `device` tool's machine), in one prepared run.
#
# Here, first (x86-64, from the repository root):
#   cargo build --release --workspace
#   bench/device.sh --pack        # .dev/: the three binaries, stripped, and the data they read
#   (and .gl/: the Vulkan loader's .deb, as the device tool's README says)
# Then on the device machine, with carry [".gl", ".dev"]:
#   bash bench/device.sh
#
# What it runs, each step's output under $OUT:
#   gpu.txt        the GPU, its driver and clocks (nvidia-smi), and vkterrain's device line
#   readback.txt   the GPU's morphed heights against the CPU mirror (--read-back-heights) on the
#                  Puget 1K and N48W125 flyovers, geomorph at tau 1 and 3 (cold and warm),
#                  discrete at tau 1
#   split.txt      N48W125 at tau 1: the device's default, discrete, whole tiles and part by part
#                  (three build costs), each with its frame, CPU, GPU and pass medians and builds
#   shots.tar      frame 0 of the Puget flyover, discrete and geomorph at tau 1 (compared with
#                  lavapipe's frames here by `bench/device.sh --compare DIR`, DIR holding
#                  shots.tar unpacked; needs Python's Pillow)
#   limit.md       `tilebench limit`: every flight with brute force, discrete and geomorph at
#                  several tau, each beside the static-mesh limit, and the paper's Table 1
# The binaries look for the shared data at a path fixed when they were built
# (tools/testdata/../../../shared/data from this checkout), so --pack writes that path down
# and the device run makes it lead to the carried copy.
set -uo pipefail
here=$(pwd)

if [ "${1:-}" = --pack ]; then
  rm -rf .dev && mkdir -p .dev/data/puget .dev/data/srtm
  for b in vkterrain tiletool tilebench; do
    cp target/release/$b .dev/ && strip .dev/$b
  done
  cp ../shared/data/puget/ps_height_1k.png ../shared/data/puget/ps_height_4k_8bit.jpg .dev/data/puget/
  cp ../shared/data/srtm/N48W125.hgt .dev/data/srtm/
  # testdata's path as the binaries hold it: the folder it starts from must exist there too.
  echo "$here/tools/testdata $(cd .. && pwd)/shared" > .dev/paths
  du -sh .dev
  exit 0
fi

if [ "${1:-}" = --compare ]; then
  # Frames from the device against the same frames drawn here (lavapipe).
  dir=$2; mkdir -p /tmp/device-shots-here
  [ -f /tmp/device-puget.vkt ] || target/release/tiletool build ../shared/data/puget/ps_height_1k.png \
    --spacing 160 --vertical-scale 0.1 -o /tmp/device-puget.vkt --quiet --force
  python3 - "$dir" <<'EOF'
import sys, os, subprocess
from PIL import Image, ImageChops
d = sys.argv[1]
for name, extra in [("discrete", ["--no-geomorph"]), ("geomorph", ["--part-by-part"])]:
    here = f"/tmp/device-shots-here/{name}"
    os.makedirs(here, exist_ok=True)
    subprocess.run(["target/release/vkterrain", "/tmp/device-puget.vkt", "--headless", "--path", "flyover",
                    "--frames", "1", "--size", "1024x768", "--tau", "1", "--out", here,
                    "--screenshot-every", "1", *extra], check=True, stdout=subprocess.DEVNULL)
    a = Image.open(f"{here}/frame_000000.png").convert("RGB")
    b = Image.open(f"{d}/{name}/frame_000000.png").convert("RGB")
    diff = ImageChops.difference(a, b).convert("L")
    px = list(diff.getdata())
    big = sum(1 for v in px if v > 24)
    print(f"{name}: mean abs difference {sum(px)/len(px):.2f} of 255, "
          f"pixels differing by more than 24: {100*big/len(px):.2f}%")
EOF
  exit 0
fi

OUT=${OUT:-/tmp/device-out}; mkdir -p "$OUT"
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
read -r testdata shared < .dev/paths
mkdir -p "$testdata" "$shared"
[ -e "$shared/data" ] || ln -s "$here/.dev/data" "$shared/data"
B=$here/.dev
V=$B/vkterrain

{
  nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm,clocks.mem --format=csv
  nproc; uname -r
} > "$OUT/gpu.txt" 2>&1

smoke() { $V - --static-grid 100000 --frames 10 --size 1024x768 > "$OUT/smoke.json" 2> "$OUT/smoke.err"; }
if ! smoke; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  if ! smoke; then
    { echo "no Vulkan device:"; cat "$OUT/smoke.err"; ldd "$V"; ldconfig -p | grep -i vulkan;
      ls -R /usr/local/nvidia/share /usr/share/vulkan /etc/vulkan 2>&1 | head -40; } | tee -a "$OUT/gpu.txt"
    exit 1
  fi
fi
grep -o '"device": *"[^"]*"' "$OUT/smoke.json" | tee -a "$OUT/gpu.txt"

# The GPU's heights against the CPU mirror, and two frames to look at.
P=/tmp/device-puget.vkt; N=/tmp/device-n48.vkt
$B/tiletool build "$B/data/puget/ps_height_1k.png" --spacing 160 --vertical-scale 0.1 -o $P --quiet --force
$B/tiletool build "$B/data/srtm/N48W125.hgt" -o $N --quiet --force
# Where an N48W125 frame goes (the H200 run found geomorph 1.8-2.8x discrete there with the pass
# itself as fast): the device's default against each mode named, and part by part at build
# costs far above lavapipe's fit, with the frame's CPU, GPU and pass medians and the builds.
for path in orbit flyover; do
  for mode in "--no-geomorph" "" "--whole-tiles" "--part-by-part" \
      "--part-by-part --part-build-cost 5000,0.2" "--part-by-part --part-build-cost 50000,1"; do
    # shellcheck disable=SC2086
    o=$($V $N --headless --path $path --frames 60 --size 1024x768 --tau 1 $mode 2>&1)
    printf 'N48W125 %s tau 1 %s: ' $path "${mode:-(default)}"
    echo "$o" | python3 -c "import json,sys; t=sys.stdin.read(); s=json.loads(t[t.index('{'):])
print(*(f'{k} {s[k]}' for k in ['part_by_part', 'frame_ms_median', 'cpu_ms_median', 'gpu_ms_median',
      'gpu_draw_ms_median', 'triangles_per_frame_mean', 'index_builds']))" 2>/dev/null || echo "$o" | tail -1
  done
done 2>&1 | tee "$OUT/split.txt"
for set in $P $N; do
  # Part by part named: it is the default on lavapipe only, and held mixes are what it checks.
  for mode in "--tau 1 --part-by-part" "--tau 3 --part-by-part" "--tau 1 --no-geomorph" \
      "--tau 1 --part-by-part --warmup" "--tau 3 --part-by-part --warmup"; do
    # shellcheck disable=SC2086
    o=$($V $set --headless --path flyover --frames 60 --size 1024x768 $mode --read-back-heights 2>&1)
    rc=$?
    printf '%s %s (exit %s): ' "$(basename $set)" "$mode" $rc
    echo "$o" | python3 -c "import json,sys; t=sys.stdin.read(); s=json.loads(t[t.index('{'):])
print('heights_read_back', s['heights_read_back'], 'heights_max_diff_m', s['heights_max_diff_m'], 'frame_ms_median', s['frame_ms_median'])" 2>/dev/null \
      || echo "$o" | tail -1
  done
done 2>&1 | tee "$OUT/readback.txt"
for name in discrete geomorph; do
  extra=--part-by-part; [ $name = discrete ] && extra=--no-geomorph
  mkdir -p /tmp/shots/$name
  $V $P --headless --path flyover --frames 1 --size 1024x768 --tau 1 --out /tmp/shots/$name \
    --screenshot-every 1 $extra > /dev/null
done
tar -C /tmp/shots -cf "$OUT/shots.tar" .

# The flight table (stdout is flushed line by line, so a stop at the limit keeps its rows).
timeout "${LIMIT_S:-480}" $B/tilebench limit 2>&1 | tee "$OUT/limit.md"
