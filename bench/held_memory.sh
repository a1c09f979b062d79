#!/bin/bash
# Freed memory held (tiles::hold_freed_memory): two vkterrain binaries, before and after,
# fly issue 25's flights in each mode, alternating within each round. Per flight and mode:
# the median frame (after frame 5) of each binary in each round, the ratio after / before
# taken within the round, and the system time of the whole run (page faults).
#   cargo build --release -p tiletool -p renderer && bash .ci/demo      # out/puget.vkt
#   bench/held_memory.sh BEFORE/vkterrain AFTER/vkterrain [ROUNDS]       # default 2
set -euo pipefail
before=$1 after=$2 rounds=${3:-2}
# shellcheck source=bench/issue25_sets.sh
source "$(dirname "$0")/issue25_sets.sh" /tmp/held-memory
rows=$out/rows.txt; : > "$rows"
for round in $(seq "$rounds"); do
  for flight in "${flights[@]}"; do
    set -- $flight
    for mode in "${modes[@]}"; do
      for b in before after; do
        bin=$before; [ $b = after ] && bin=$after
        # shellcheck disable=SC2086
        /usr/bin/time -f "%S" -o "$out/sys" "$bin" "$1" --headless --path "$2" --frames 60 \
          --size 1024x768 $mode --log "$out/log.csv" > /dev/null
        python3 - "$round" "$(basename "$1" .vkt) $2" "$mode" "$b" "$out/log.csv" "$out/sys" >> "$rows" <<'PY'
import csv, sys
r = list(csv.DictReader(open(sys.argv[5])))[5:]
v = sorted(float(x["frame_ms"]) for x in r)
print("|".join(sys.argv[1:5] + ["%.2f" % v[len(v) // 2], open(sys.argv[6]).read().strip()]))
PY
      done
    done
  done
done
python3 - "$rows" <<'PY'
import collections, statistics, sys
t = collections.defaultdict(dict)
for line in open(sys.argv[1]):
    rnd, flight, mode, b, frame, sys_s = line.strip().split("|")
    t[(flight, mode)].setdefault(int(rnd), {})[b] = (float(frame), float(sys_s))
print("| flight | mode | frame ms before (rounds) | after (rounds) | after / before (median) | system s before, after |")
print("|---|---|---|---|---:|---|")
for (flight, mode), rounds in t.items():
    rs = sorted(rounds)
    f = lambda b: ", ".join("%.1f" % rounds[r][b][0] for r in rs)
    s = lambda b: statistics.median(rounds[r][b][1] for r in rs)
    ratio = statistics.median(rounds[r]["after"][0] / rounds[r]["before"][0] for r in rs)
    print(f"| {flight} | {mode} | {f('before')} | {f('after')} | {ratio:.2f}x | {s('before'):.2f}, {s('after'):.2f} |")
PY
