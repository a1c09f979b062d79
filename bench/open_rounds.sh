#!/bin/bash
# Open and first frame of the same tile sets by two vkterrain binaries, alternating within
# each round so that the machine's drift falls on both alike: for each set and binary, the
# process's `open_ms` and its wall time to the end of one drawn frame (the orbit's first,
# `--pyramid`, 1024 x 768), then the medians over rounds.
#   usage: bench/open_rounds.sh ROUNDS BEFORE AFTER SET.vkt...
# e.g. bench/open_rounds.sh 3 /tmp/vkterrain.before target/release/vkterrain m1l2.vkt m16l2.vkt m64l2.vkt
# (sets as bench/scale64.sh makes them).
set -euo pipefail
rounds=$1 before=$2 after=$3; shift 3
out=${OUT:-/tmp/open-rounds}; mkdir -p "$out"
rows=$out/rows.txt; : > "$rows"
for round in $(seq "$rounds"); do
  for vkt in "$@"; do
    for bin in "$before" "$after"; do
      /usr/bin/time -f "%e" -o "$out/time" "$bin" "$vkt" --headless --pyramid --path orbit \
        --frames 1 --size 1024x768 > "$out/summary.json" 2>/dev/null
      python3 - "$(basename "$vkt")" "$bin" "$out" >> "$rows" <<'PY'
import json, sys
name, bin, out = sys.argv[1:]
j = json.load(open(f"{out}/summary.json"))
print(name, bin, j["open_ms"], open(f"{out}/time").read().strip())
PY
    done
  done
done
python3 - "$rows" <<'PY'
import collections, statistics, sys
runs = collections.defaultdict(list)
for line in open(sys.argv[1]):
    name, bin, open_ms, wall = line.split()
    runs[(name, bin)].append((float(open_ms), float(wall)))
print("| set | binary | open ms, each round | median | first frame s, each round | median |")
print("|---|---|---|---:|---|---:|")
for (name, bin), r in runs.items():
    o = [x[0] for x in r]; w = [x[1] for x in r]
    print(f"| {name} | {bin} | {', '.join(f'{x:.1f}' for x in o)} | {statistics.median(o):.1f} | "
          f"{', '.join(f'{x:.2f}' for x in w)} | {statistics.median(w):.2f} |")
PY
