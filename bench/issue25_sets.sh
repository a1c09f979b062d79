# Sourced by issue 25's round scripts (bench/rounds.sh, bench/made.sh): the binaries, the
# scratch folder ($out, from OUT or the script's default $1), the demo's Puget set ($P) and the
# SRTM N48W125 set built with the default options ($N, as bench/device.sh builds it), and the
# modes of issue 25's table.
B=target/release
out=${OUT:-$1}; mkdir -p "$out"
P=out/puget.vkt
N=$out/n48.vkt
[ -f "$P" ] || { echo "$0: $P is missing: run bash .ci/demo first" >&2; exit 2; }
[ -f "$N" ] || $B/tiletool build ../shared/data/srtm/N48W125.hgt -o "$N" --quiet --force
modes=("--no-geomorph --tau 1" "--tau 1" "--tau 3" "--brute-force")
