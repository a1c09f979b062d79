#!/bin/bash
# The error a cut delivers, measured (`vkterrain --pyramid --measure-error`) against the base
# grid's, 30 frames a flight, every frame measured. Sets: /tmp/m1p.vkt and /tmp/m4p.vkt
# (GENERATED mirror sets, bench/README "The cut drawn") and their raw sources /tmp/m1.r16, m4.r16.
# usage: bench/meter_cut.sh   (from the repository root, after cargo build --release)
V=target/release/vkterrain
echo "| set | flight | drawn as | tau | max_error_px, largest frame | median frame | frames with layer tiles | layer tiles (median) | triangles (median) |"
echo "|---|---|---|---:|---:|---:|---:|---:|---:|"
for set in m1:1025 m4:4097; do n=${set%%:*}; sz=${set##*:}
 for path in orbit flyover; do for tau in 1 3; do for mode in base pyramid; do
  # Discrete levels both ways (`--pyramid` geomorphs since e5b6866).
  f="--no-geomorph"; [ $mode = pyramid ] && f="--pyramid --no-geomorph"
  $V /tmp/${n}p.vkt --headless --path $path --frames 30 --size 1024x768 $f --tau $tau --upload-budget-mb=100000 \
    --measure-error /tmp/$n.r16 --source-size ${sz}x$sz --source-spacing 90 --log /tmp/mb.csv > /dev/null
  python3 - $n $path $mode $tau <<'PY'
import csv, statistics, sys
n, path, mode, tau = sys.argv[1:]
r = list(csv.DictReader(open('/tmp/mb.csv')))
c = lambda k: [float(x[k]) for x in r]
name = {'m1': 'mirror 1025²', 'm4': 'mirror 4097²'}[n]
print(f"| {name} | {path} | {'cut' if mode == 'pyramid' else 'base grid'} | {tau} | {max(c('max_error_px')):.3f} | {statistics.median(c('max_error_px')):.3f} | {sum(1 for v in c('tiles_above_base') if v > 0)} of {len(r)} | {statistics.median(c('tiles_above_base')):.0f} | {statistics.median(c('triangles')):.0f} |")
PY
 done; done; done; done
# Pops on the ground (bench/README, "The error over a cut, measured"): the 4K set's flyover,
# first 12 s at 30 frames a second, as bench/pyramid.sh cuts it (its m4p.start.csv), e.g.
#   target/release/vkterrain /tmp/m4p.vkt --headless --path /tmp/pyramid-bench/m4p.start.csv \
#     --frames 120 --size 480x360 [--no-geomorph | --pyramid --no-geomorph | --tau 1 | --pyramid] \
#     --upload-budget-mb 100000 \
#     --measure-error /tmp/m4.r16 --source-size 4097x4097 --source-spacing 90 --log pops.csv
