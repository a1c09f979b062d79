# Sourced by issue 25's round scripts (bench/rounds.sh, bench/made.sh): the binaries, the
# scratch folder ($out, from OUT or the script's default $1), the demo's Puget set ($P) and the
# SRTM N48W125 set built with the default options ($N, as bench/device.sh builds it), and the
# modes and flights of issue 25's table, and `fly`, which flies one of them (with the binary
# $VK when set).
B=target/release
out=${OUT:-$1}; mkdir -p "$out"
P=out/puget.vkt
N=$out/n48.vkt
[ -f "$P" ] || { echo "$0: $P is missing: run bash .ci/demo first" >&2; exit 2; }
[ -f "$N" ] || $B/tiletool build ../shared/data/srtm/N48W125.hgt -o "$N" --quiet --force
modes=("--no-geomorph --tau 1" "--tau 1" "--tau 3" "--brute-force")
flights=("$P flyover" "$P orbit" "$N flyover" "$N orbit")
# fly SET PATH OPTION...: one flight of a round, 60 frames at 1024x768, its log in $out/log.csv.
fly() {
  local set=$1 path=$2
  shift 2
  "${VK:-$B/vkterrain}" "$set" --headless --path "$path" --frames 60 --size 1024x768 "$@" \
    --log "$out/log.csv" > /dev/null
}
