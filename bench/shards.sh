#!/bin/bash
# Distributed builds (issue 29): a mirror set built without shards, then through a local
# single-node Slurm (deploy/slurm/local-cluster.sh) as N = 1, 2 and 4 array tasks and the
# merge that depends on them. Prints wall times, each shard's peak memory, the merge's time
# and whether the merged set is the unsharded build's bytes.
# The set is GENERATED: a mirror tiling of the real SRTM3 tile N55W003 (bench/mirror.py),
# made under $OUT and never committed (the 16K set's raw file is 537 MB, each set 5.8 GB).
# Run from the repository root, as root, after `cargo build --release -p tiletool`.
# usage: bench/shards.sh [SIZE] [SHARDS...]   (default: 16385 1 2 4; 4s: 4 shards after the
# scan stage, each reading only its rows). EXTRA="--pyramid" adds build options (word-split).
# TILETOOL_BIN picks the binary.
set -euo pipefail
root=$(pwd)
T=${TILETOOL_BIN:-$root/target/release/tiletool}
out=${OUT:-/tmp/shards-bench}; mkdir -p "$out"
size=${1:-16385}; shift || true
counts=${*:-"1 2 4"}
raw=$out/m$size.r16
[ -f "$raw" ] || python3 bench/mirror.py ../shared/data/srtm/N55W003.hgt "$size" "$raw"
# shellcheck disable=SC2206 # EXTRA is split into words on purpose
opts=(--size "${size}x$size" --spacing 90 ${EXTRA:-})

/usr/bin/time -f "%e %M" -o "$out/whole.time" "$T" build "$raw" "${opts[@]}" --quiet -o "$out/whole.vkt"
read -r wall kb < "$out/whole.time"
printf "unsharded build: %.0f s, peak %.0f MB, file %.0f MB\n" "$wall" "$((kb / 1024))" \
  "$(($(stat -c %s "$out/whole.vkt") / 1000000))"

# Every tiletool run of the array and the merge timed into $out/times.
cat > "$out/tiletool-timed" <<SH
#!/bin/bash
exec /usr/bin/time -f "%e %M" -o "$out/times/\${SLURM_ARRAY_JOB_ID:-\$SLURM_JOB_ID}-\${SLURM_ARRAY_TASK_ID:-merge}" "$T" "\$@"
SH
chmod +x "$out/tiletool-timed"
state=/tmp/vkt-shards-slurm
deploy/slurm/local-cluster.sh start "$state" >/dev/null
trap 'deploy/slurm/local-cluster.sh stop "$state" >/dev/null' EXIT
export SLURM_CONF=$state/slurm.conf TILETOOL=$out/tiletool-timed
# A count with an s (4s) runs the scan stage first (submit.sh's SCAN=1).
for spec in $counts; do
  n=${spec%s}; scan=0; [ "$spec" != "$n" ] && scan=1
  rm -rf "$out/parts" "$out/times" "$out/merged.vkt"; mkdir -p "$out/times"
  start=$(date +%s.%N)
  read -r array merge < <(cd "$out" && SCAN=$scan "$root/deploy/slurm/submit.sh" "$n" "$out/parts" "$out/merged.vkt" "$raw" "${opts[@]}")
  while [ -n "$(squeue -h -j "$array,$merge")" ]; do sleep 1; done
  end=$(date +%s.%N)
  same=$(cmp -s "$out/merged.vkt" "$out/whole.vkt" && echo "same bytes" || echo "DIFFERENT")
  shards=$(for f in "$out/times/$array"-[0-9]*; do read -r w k < "$f"; printf "%.0f s/%.0f MB " "$w" "$((k / 1024))"; done)
  read -r mw mk < "$out/times/$merge-merge"
  printf "N=%s%s: wall %.0f s (submission to merged set); shards (time/peak): %s; merge %.1f s, peak %.0f MB; %s\n" \
    "$n" "$([ $scan = 1 ] && echo ' with scans')" "$(echo "$end - $start" | bc)" "$shards" "$mw" "$((mk / 1024))" "$same"
  if [ $scan = 1 ]; then
    scans=$(for f in "$out/times"/*; do case $f in *"/$array-"*|*-merge) ;; *) read -r w k < "$f"; printf "%.0f s/%.0f MB " "$w" "$((k / 1024))";; esac; done)
    echo "    scan stage (time/peak): $scans"
  fi
  grep -h "input read" "$out"/vkt-shard-"$array"_*.log | sed 's/.*input read/    input read/; s/, peak.*//'
  rm -f "$out"/vkt-shard-*.log
  grep -h "seams\|units\|pyramid\|layer tiles" "$out"/vkt-merge-"$merge".log | sed 's/^/    /'
done
rm -rf "$out/parts" "$out/merged.vkt"
