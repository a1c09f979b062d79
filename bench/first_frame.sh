#!/bin/bash
# The time a process takes to open a set and draw one frame (file warm; best of 2 runs),
# that first view's checks and the open itself: prints "WALL_S CHECK_MS OPEN_MS". Shared by
# bench/cut_tables.sh and bench/level_checks.sh.
# usage: bench/first_frame.sh VKTERRAIN SET.vkt PATH OUT_PREFIX [FLAGS...]
set -euo pipefail
bin=$1 vkt=$2 path=$3 run=$4; shift 4
for i in 1 2; do
  /usr/bin/time -f "%e" -o "$run.first$i.time" \
    "$bin" "$vkt" --headless --path "$path" --frames 1 --size 1024x768 "$@" > "$run.first$i.json" 2>/dev/null
done
python3 - "$run" <<'PY'
import json, sys
run = sys.argv[1]
firsts = []
for i in (1, 2):
    wall = float(open(f"{run}.first{i}.time").read().split()[0])
    summary = json.load(open(f"{run}.first{i}.json"))
    firsts.append((wall, summary["first_view_check_ms"], summary["open_ms"]))
print(*min(firsts))
PY
