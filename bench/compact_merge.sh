#!/bin/bash
# Issue 29 with --compact: where a compact set's tiles are compacted, on the shards or in the
# merge. Each tiletool binary given builds every input unsharded and in 4 shards with
# --compact; then the merges of each binary's parts run in alternating rounds (this machine's
# speed moves from minute to minute). Prints, per input and binary: the unsharded build's
# wall time, the shards' summed wall time and part bytes, the merge's median wall time and its
# share of the unsharded build, the tiles sealed again, and whether the merged set is the
# build's bytes.
# Inputs: SRTM1 N48W125 and the 4K Puget (real; their shards' morph units differ from the
# set's, so the merge seals most tiles again), and a GENERATED 4097² mirror tiling of SRTM3
# N55W003 (bench/mirror.py; every shard needs the set's units, so the merge copies).
# usage: bench/compact_merge.sh TILETOOL...   (ROUNDS, default 3; OUT, default /tmp/compact-merge)
set -euo pipefail
rounds=${ROUNDS:-3}
out=${OUT:-/tmp/compact-merge}; mkdir -p "$out"
data=${DATA:-../shared/data}
raw=$out/m4097.r16
[ -f "$raw" ] || python3 bench/mirror.py "$data/srtm/N55W003.hgt" 4097 "$raw"
inputs=(
  "n48w125|$data/srtm/N48W125.hgt"
  "puget4k|$data/puget/ps_height_4k_8bit.jpg --spacing 40 --vertical-scale 25.7"
  "mirror4k|$raw --size 4097x4097 --spacing 90"
)
n=4
rows=$out/rows.txt; : > "$rows"
for spec in "${inputs[@]}"; do
  IFS='|' read -r name args <<< "$spec"
  for b in $(seq $#); do
    bin=${!b}
    d=$out/$name.$b; rm -rf "$d"; mkdir -p "$d"
    # shellcheck disable=SC2086
    /usr/bin/time -f "%e" -o "$d/t" "$bin" build $args --compact -o "$d/whole.vkt" --quiet
    whole=$(cat "$d/t")
    shards=0
    for k in $(seq 0 $((n - 1))); do
      # shellcheck disable=SC2086
      /usr/bin/time -f "%e" -o "$d/t" "$bin" build $args --compact --shard "$k/$n" -o "$d/part.$k" --quiet
      shards=$(python3 -c "print($shards + $(cat "$d/t"))")
    done
    bytes=$(cat "$d"/part.* | wc -c)
    echo "$name|$b|build|$whole|$shards|$bytes" >> "$rows"
  done
  for r in $(seq "$rounds"); do
    for b in $(seq $#); do
      bin=${!b}
      d=$out/$name.$b
      /usr/bin/time -f "%e" -o "$d/t" "$bin" merge "$d"/part.* -o "$d/merged.vkt" --force > "$d/said"
      same=no; cmp -s "$d/merged.vkt" "$d/whole.vkt" && same=yes
      sealed=$(grep -o "[0-9]* tiles sealed again" "$d/said" | cut -d' ' -f1 || true)
      echo "$name|$b|merge|$r|$(cat "$d/t")|${sealed:-0}|$same" >> "$rows"
    done
  done
done
python3 - "$rows" "$@" <<'PY'
import collections, statistics, sys
rows = [l.strip().split("|") for l in open(sys.argv[1])]
bins = sys.argv[2:]
build = {(r[0], int(r[1])): r[3:] for r in rows if r[2] == "build"}
merges = collections.defaultdict(list)
for r in rows:
    if r[2] == "merge":
        merges[(r[0], int(r[1]))].append(r[3:])
print("| input | binary | unsharded build, s | 4 shards, summed s | parts, MB | merge, s (each round) | median | merge / build | tiles sealed again | same bytes |")
print("|---|---|---:|---:|---:|---|---:|---:|---:|---|")
for (name, b), (whole, shards, size) in build.items():
    m = merges[(name, b)]
    times = [float(x[1]) for x in m]
    med = statistics.median(times)
    print(f"| {name} | {bins[b - 1]} | {float(whole):.2f} | {float(shards):.2f} | {int(size) / 1e6:.1f} | "
          f"{', '.join(f'{t:.2f}' for t in times)} | {med:.2f} | {100 * med / float(whole):.1f}% | "
          f"{m[0][2]} | {'yes' if all(x[3] == 'yes' for x in m) else 'NO'} |")
PY
