#!/bin/bash
# Sharded builds of inputs with voids (issue 29): what each shard reads of its input and how
# long each stage takes, without the scan stages (every shard reads the whole input to scan
# it and plan its void fill) and with them (scan, ranges, build: each shard reads only its
# rows, with the margin their voids' fill needs). Real SRTM data, no generated set:
# N48W125 (SRTM1, half of it sea: 6.5 M voids of 13 M samples), the mosaic N41E001 +
# N42E001 (SRTM3, 7.8 k voids over both tiles) and N55W003 (SRTM3, no void: the scans' old
# case). Every merged set is compared with the unsharded build (`cmp`).
# Run from the repository root after `cargo build --release -p tiletool`.
# usage: bench/scan_voids.sh [SHARDS]   (default 4; ONLY=1: N48W125 alone, which has 15 tile
# rows, for more shards than the others' 5 and 10)
set -euo pipefail
T=${TILETOOL_BIN:-target/release/tiletool}
n=${1:-4}
out=${OUT:-/tmp/scan-voids-bench}; rm -rf "$out"; mkdir -p "$out"
srtm=../shared/data/srtm

# run NAME TILETOOL-ARGS...: the run's wall seconds and MB read (the kernel's rchar of the
# process: every read() of the input and of the scan files) into $out/t/NAME.
mkdir -p "$out/t"
run() {
  local name=$1; shift
  local start end rchar
  start=$(date +%s.%N)
  rchar=$(sh -c '"$@" > /dev/null; grep "^rchar" /proc/$$/io' sh "$T" "$@" | awk '{print $2}')
  end=$(date +%s.%N)
  echo "$(echo "$end - $start" | bc) $(echo "scale=1; $rchar / 1000000" | bc)" > "$out/t/$name"
}
sum() { awk '{w += $1; r += $2; if ($2 > m) m = $2} END {printf "%.2f %.1f %.1f", w, r, m}' "$@"; }

echo "| input | input MB | voids | unsharded build s | without scans: shards s, MB read (sum, largest) | scan: s, MB read | ranges: s, MB read | build with scans: s, MB read (sum, largest) | same bytes |"
echo "|---|---:|---:|---:|---|---|---|---|---|"
cases=("N48W125:$srtm/N48W125.hgt" "N41E001+N42E001:$srtm/N41E001.hgt $srtm/N42E001.hgt"
  "N55W003:$srtm/N55W003.hgt")
[ -n "${ONLY:-}" ] && cases=("${cases[@]:0:$ONLY}")
for case in "${cases[@]}"; do
  name=${case%%:*}
  read -r -a input <<< "${case#*:}"
  opts=(--no-texture)
  mb=$(du -cb "${input[@]}" | tail -1 | awk '{printf "%.1f", $1 / 1e6}')
  run whole build "${input[@]}" "${opts[@]}" -o "$out/whole.vkt" --force
  voids=$("$T" info "$out/whole.vkt" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["voids_filled"])')
  mkdir -p "$out/scans-$name"
  for k in $(seq 0 $((n - 1))); do
    run "plain-$k" build "${input[@]}" "${opts[@]}" --shard "$k/$n" -o "$out/plain-$k.part" --force
  done
  for k in $(seq 0 $((n - 1))); do
    run "scan-$k" build "${input[@]}" "${opts[@]}" --shard "$k/$n" --scan-only \
      -o "$out/scans-$name/scan-$k-of-$n.vktscan"
  done
  for k in $(seq 0 $((n - 1))); do
    run "ranges-$k" build "${input[@]}" "${opts[@]}" --shard "$k/$n" --scans "$out/scans-$name" \
      --ranges-only -o "$out/scans-$name/ranges-$k-of-$n.vktranges"
  done
  for k in $(seq 0 $((n - 1))); do
    run "scanned-$k" build "${input[@]}" "${opts[@]}" --shard "$k/$n" --scans "$out/scans-$name" \
      -o "$out/scanned-$k.part" --force
  done
  same=yes
  "$T" merge "$out"/plain-*.part -o "$out/plain.vkt" --quiet --force
  "$T" merge "$out"/scanned-*.part -o "$out/scanned.vkt" --quiet --force
  cmp -s "$out/plain.vkt" "$out/whole.vkt" || same=no
  cmp -s "$out/scanned.vkt" "$out/whole.vkt" || same=no
  read -r pw pr pm <<< "$(sum "$out"/t/plain-*)"
  read -r sw sr _ <<< "$(sum "$out"/t/scan-*)"
  read -r rw rr _ <<< "$(sum "$out"/t/ranges-*)"
  read -r bw br bm <<< "$(sum "$out"/t/scanned-*)"
  printf "| %s | %s | %s | %.2f | %.2f, %s (%s) | %.2f, %s | %.2f, %s | %.2f, %s (%s) | %s |\n" \
    "$name" "$mb" "$voids" "$(cut -d' ' -f1 "$out/t/whole")" "$pw" "$pr" "$pm" "$sw" "$sr" \
    "$rw" "$rr" "$bw" "$br" "$bm" "$same"
done
