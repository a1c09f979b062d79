#!/usr/bin/env bash
# Compact levels on the bus (issue 28, "refinement bytes" and "GPU decode time"): each flight
# over a compact set (tiletool build --compact, format version 5) flown three ways, alternating:
#   rows:  --decode cpu --morph-rows  each block as positions and morph rows (the blocks of
#          83b01c5, the issue's baseline)
#   cpu:   --decode cpu               positions alone (the CPU rebuilt them at the tile's check)
#   gpu:   --decode gpu               each level's compact stream, decoded on the GPU (the default on a GPU)
# at the default upload budget, and cpu and gpu again at tight budgets: block bytes sent,
# tile-frames drawn coarser than wanted, the pool's largest resident set, triangles, median
# frame, and the GPU time outside the draws (copies, decodes, index builds, morph pass).
# Usage: bench/decode.sh SET.vkt...   (after cargo build --release; BUDGETS="0.5 0.25")
set -euo pipefail
V=target/release/vkterrain
budgets=${BUDGETS:-0.5 0.25}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "| set | flight | budget MiB | mode | block MB sent | against rows | against cpu | tile-frames coarser | resident MB (largest) | triangles (median) | frame ms (median after frame 5) | outside the draws ms: median after frame 5, mean, frame 0 |"
echo "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|"
for set in "$@"; do
  for path in flyover orbit; do
    runs=("4 rows" "4 cpu" "4 gpu")
    for budget in $budgets; do runs+=("$budget cpu" "$budget gpu"); done
    for run in "${runs[@]}"; do
      read -r budget mode <<< "$run"
      case $mode in
        rows) flags=(--decode cpu --morph-rows) ;;
        cpu) flags=(--decode cpu) ;;
        gpu) flags=(--decode gpu) ;;
      esac
      $V "$set" --headless --path $path --frames 120 --size 1024x768 --tau 1 \
        --upload-budget-mb "$budget" "${flags[@]}" --log "$out/$budget-$mode.csv" > /dev/null
      python3 - "$out" "$(basename "$set")" $path "$budget" $mode <<'PY'
import csv, os, statistics, sys
out, name, path, budget, mode = sys.argv[1:]
rows = lambda m: list(csv.DictReader(open(os.path.join(out, f"{budget if m != 'rows' else '4'}-{m}.csv"))))
r = rows(mode)
total = lambda rr, k: sum(float(x[k]) for x in rr)
med = lambda k, rr: statistics.median(float(x[k]) for x in rr)
sent = total(r, 'upload_bytes_blocks')
def against(m):
    f = os.path.join(out, f"{budget if m != 'rows' else '4'}-{m}.csv")
    return f"{sent / total(rows(m), 'upload_bytes_blocks'):.2f}x" if os.path.exists(f) and m != mode else ""
outside = [float(x['gpu_ms']) - float(x['gpu_draw_ms']) for x in r]
print(f"| {name} | {path} | {budget} | {mode} | {sent / 1e6:.2f} | {against('rows')} | {against('cpu')} "
      f"| {total(r, 'tiles_coarser'):.0f} | {max(float(x['resident_bytes']) for x in r) / 1e6:.1f} "
      f"| {med('triangles', r):.0f} | {med('frame_ms', r[5:]):.1f} "
      f"| {statistics.median(outside[5:]):.1f}, {statistics.mean(outside[5:]):.1f}, {outside[0]:.1f} |")
PY
    done
    rm -f "$out"/*.csv
  done
done
