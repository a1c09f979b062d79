#!/usr/bin/env python3
"""Writes a mirror tiling of a real SRTM tile as a raw little-endian .r16 grid: GENERATED
test data for the scale benchmarks (bench/scale.sh), not a real place. The tile is reflected
at every edge (columns and rows run 0..S-1, S-2..0, 1..S-1, ...), so the grid is continuous
and every sample is a real SRTM height; voids (-32768) and heights below 0 become 0.

usage: mirror.py SOURCE.hgt SIZE OUT.r16     (SIZE samples per side, e.g. 16385)

Deterministic: the same source and size give the same bytes. Pure Python (no numpy): each
output row is one of the source's rows, mirrored across, built once and written as bytes.
"""
import array
import os
import sys


def mirrored(i, s):
    """Source index of output index i in a reflection of 0..s-1."""
    j = i % (2 * (s - 1))
    return j if j < s else 2 * (s - 1) - j


def main():
    if len(sys.argv) != 4:
        sys.exit("usage: mirror.py SOURCE.hgt SIZE OUT.r16")
    source, size, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    raw = open(source, "rb").read()
    side = int(round((len(raw) // 2) ** 0.5))
    if side * side * 2 != len(raw) or side < 2:
        sys.exit(f"mirror.py: {source}: not a square SRTM .hgt ({len(raw)} bytes)")
    heights = array.array("h", raw)
    if sys.byteorder == "little":
        heights.byteswap()  # .hgt is big-endian
    columns = [mirrored(i, side) for i in range(size)]
    rows = {}
    tmp = out + ".tmp"
    with open(tmp, "wb") as f:
        for y in range(size):
            r = mirrored(y, side)
            if r not in rows:
                line = heights[r * side:(r + 1) * side]
                values = array.array("H", (max(0, line[c]) for c in columns))
                if sys.byteorder != "little":
                    values.byteswap()
                rows[r] = values.tobytes()
            f.write(rows[r])
    os.replace(tmp, out)


if __name__ == "__main__":
    main()
