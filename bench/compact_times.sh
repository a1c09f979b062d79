#!/bin/bash
# Issue 28's "build and verify no worse than version 3": each tiletool binary given builds
# every input as version 3 and with --compact, and verifies both, alternating within each
# round (this machine's speed moves from minute to minute); per binary and input, the median
# wall and CPU seconds and the compact set's ratio to version 3's, taken within each round.
# Inputs: the demo's Puget 1K with its photo and SRTM1 N48W125 with the default relief texture.
# usage: bench/compact_times.sh TILETOOL... (ROUNDS, default 3)
set -euo pipefail
rounds=${ROUNDS:-3}
out=${OUT:-/tmp/compact-times}; mkdir -p "$out"
data=${DATA:-../shared/data}
inputs=(
  "puget|sample/ps_height_1k.png --spacing 160 --vertical-scale 0.1 --texture sample/ps_texture_1k.png"
  "n48w125|$data/srtm/N48W125.hgt"
)
rows=$out/rows.txt; : > "$rows"
for spec in "${inputs[@]}"; do
  IFS='|' read -r name args <<< "$spec"
  for r in $(seq "$rounds"); do
    for b in $(seq $#); do
      bin=${!b}
      for form in v3 compact; do
        flag=; [ $form = compact ] && flag=--compact
        set_=$out/$name.$b.$form.vkt
        # shellcheck disable=SC2086
        /usr/bin/time -f "%e %U" -o "$out/t" "$bin" build $args $flag -o "$set_" --quiet --force
        echo "$name|$b|$r|build|$form|$(cat "$out/t")" >> "$rows"
        /usr/bin/time -f "%e %U" -o "$out/t" "$bin" verify "$set_" > /dev/null
        echo "$name|$b|$r|verify|$form|$(cat "$out/t")" >> "$rows"
      done
    done
  done
done
python3 - "$rows" "$@" <<'PY'
import collections, statistics, sys
t = collections.defaultdict(dict)
for line in open(sys.argv[1]):
    name, b, r, step, form, times = line.strip().split("|")
    t[(name, int(b), step)].setdefault(form, {})[int(r)] = [float(x) for x in times.split()]
print("| input | binary | step | version 3: wall, CPU s | compact: wall, CPU s | compact / version 3, wall (each round) | median |")
print("|---|---|---|---|---|---|---:|")
for (name, b, step), forms in t.items():
    v3, c = forms["v3"], forms["compact"]
    med = lambda d, k: statistics.median(x[k] for x in d.values())
    ratios = [c[r][0] / v3[r][0] for r in sorted(v3)]
    print(f"| {name} | {sys.argv[1 + b]} | {step} | {med(v3, 0):.2f}, {med(v3, 1):.2f} | {med(c, 0):.2f}, {med(c, 1):.2f} "
          f"| {', '.join('%.2f' % x for x in ratios)} | {statistics.median(ratios):.2f}x |")
PY
