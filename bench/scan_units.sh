#!/usr/bin/env bash
# Morph units from the scan, and tables without the offsets' rounding (issue 29, the merge that
# sealed tiles again; issue 25, what the morph pass draws): each pair of binaries (tiletool and
# vkterrain, before and after) builds the Puget sample, N48W125 and the 4K Puget, and flies its
# own sets. Prints the median triangles of the flyover and orbit (60 frames, 1024 x 768, tau 1),
# then errors, pops and triangles measured warm against the source on every frame, on the
# flights closest to tau (those of bench/parents_weight.sh).
# Usage: bench/scan_units.sh BEFORE_TILETOOL BEFORE_VKTERRAIN   (after cargo build --release;
#   the after binaries are this tree's; OUT, default /tmp/scan-units, keeps the sets)
set -euo pipefail
out=${OUT:-/tmp/scan-units}; mkdir -p "$out"
data=${DATA:-../shared/data}
tools=("$1" target/release/tiletool)
views=("$2" target/release/vkterrain)
for b in 0 1; do
  t=${tools[$b]}
  "$t" build sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 \
    --texture sample/ps_texture_1k.png -o "$out/puget.$b.vkt" --quiet
  "$t" build "$data/srtm/N48W125.hgt" -o "$out/n48.$b.vkt" --quiet
  "$t" build "$data/puget/ps_height_4k_8bit.jpg" --spacing 40 --vertical-scale 25.7 \
    -o "$out/p4k.$b.vkt" --quiet
done
median_triangles() {
  python3 -c "import csv, statistics, sys; r = list(csv.DictReader(open(sys.argv[1])))[5:]; print(int(statistics.median(int(x['triangles']) for x in r)))" "$1"
}
echo "| set | flight | triangles before | after | after / before |"
echo "|---|---|---:|---:|---:|"
for set in puget n48 p4k; do
  for path in flyover orbit; do
    t=()
    for b in 0 1; do
      "${views[$b]}" "$out/$set.$b.vkt" --headless --path $path --frames 60 --size 1024x768 \
        --tau 1 --log "$out/f.csv" > /dev/null
      t+=("$(median_triangles "$out/f.csv")")
    done
    echo "| $set | $path | ${t[0]} | ${t[1]} | $(python3 -c "print(f'{${t[1]} / ${t[0]}:.4f}')") |"
  done
done
P="--measure-error sample/ps_height_1k.png --source-spacing 160 --source-vertical-scale 0.1"
N="--measure-error $data/srtm/N48W125.hgt"
K="--measure-error $data/puget/ps_height_4k_8bit.jpg --source-spacing 40 --source-vertical-scale 25.7"
# The first 12 s of each set's flyover, as tilebench table1 cuts them.
for set in puget n48 p4k; do
  target/release/vkterrain "$out/$set.1.vkt" --headless --path flyover --frames 1 --size 64x48 \
    --record "$out/keys.csv" > /dev/null 2>&1
  awk -F, 'NR == 1 || $1 <= 12' "$out/keys.csv" > "$out/$set.start.csv"
done
echo
echo "| flight | tau | max_error_px before | after | pop_px before | after | frames over 0.5 px before | after | triangles (median) before | after |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
# row NAME SET TAU ARGS...: each pair flies its own SET with ARGS, warm, every frame measured.
row() {
  local name=$1 set=$2 tau=$3 r=(); shift 3
  for b in 0 1; do
    "${views[$b]}" "$out/$set.$b.vkt" "$@" --warmup --tau "$tau" --log "$out/f.csv" > /dev/null
    r+=("$(python3 - "$out/f.csv" <<'PY'
import csv, statistics, sys
r = list(csv.DictReader(open(sys.argv[1])))
pops = [float(x['pop_px']) for x in r[1:]]
print(max(float(x['max_error_px']) for x in r), max(pops), sum(p > 0.5 for p in pops),
      int(statistics.median(float(x['triangles']) for x in r)))
PY
)")
  done
  local e1 p1 n1 t1 e2 p2 n2 t2
  read -r e1 p1 n1 t1 <<< "${r[0]}"
  read -r e2 p2 n2 t2 <<< "${r[1]}"
  printf '| %s | %s | %.3f | %.3f | %.3f | %.3f | %d | %d | %d | %d |\n' \
    "$name" "$tau" "$e1" "$e2" "$p1" "$p2" "$n1" "$n2" "$t1" "$t2"
}
for tau in 1 3; do
  row "4K Puget flyover, 120 frames, 1024 x 768" p4k $tau --headless --path flyover --frames 120 --size 1024x768 $K
done
for tau in 3 5; do
  row "4K Puget flyover, first 12 s, 360 frames, 480 x 360" p4k $tau --headless --path "$out/p4k.start.csv" --frames 360 --size 480x360 $K
done
row "Puget flyover, first 12 s, 360 frames, 480 x 360" puget 5 --headless --path "$out/puget.start.csv" --frames 360 --size 480x360 $P
row "N48W125 flyover, first 12 s, 360 frames, 480 x 360" n48 5 --headless --path "$out/n48.start.csv" --frames 360 --size 480x360 $N
row "Puget flyover, 120 frames, 1024 x 768" puget 1 --headless --path flyover --frames 120 --size 1024x768 $P
row "N48W125 orbit, 120 frames, 1024 x 768" n48 1 --headless --path orbit --frames 120 --size 1024x768 $N
