// A tile's 4 x 4 parts (64 x 64 cells each) and the levels they are drawn at, as the host packs
// them (tools/tiles/src/parts.rs, packed_levels: part 4 j + i at bits 4 (k % 8) of word k / 8),
// and which level's blocks the mixed mesh takes at a lattice point (its presence_level, the
// CPU side): included by indices.comp, which builds the mesh, and morph.comp, which places its
// vertices, so that the two agree by construction.

// The level of part (i, j).
uint packed_part_level(uvec2 parts, uint i, uint j) {
    uint k = j * 4u + i;
    return (parts[k / 8u] >> (4u * (k % 8u))) & 15u;
}

// The levels of the four parts (some the same) whose closed boxes hold lattice point (x, y)
// inside the tile (not on its border).
uvec4 holding_levels(uvec2 parts, uint x, uint y) {
    uint i1 = x / 64u, j1 = y / 64u;
    uint i0 = x % 64u == 0u ? i1 - 1u : i1;
    uint j0 = y % 64u == 0u ? j1 - 1u : j1;
    return uvec4(packed_part_level(parts, i0, j0), packed_part_level(parts, i1, j0),
                 packed_part_level(parts, i0, j1), packed_part_level(parts, i1, j1));
}

bool on_tile_border(uint x, uint y) {
    return x == 0u || y == 0u || x >= 256u || y >= 256u;
}

// The level whose blocks give lattice point (x, y) its vertices: the part's inside a part,
// the finest of the parts that meet at a line, `top` (the finest of all) on the tile's border.
uint packed_presence_level(uvec2 parts, uint x, uint y, uint top) {
    if (on_tile_border(x, y)) {
        return top;
    }
    uvec4 l = holding_levels(parts, x, y);
    return max(max(l.x, l.y), max(l.z, l.w));
}

// The level of the coarsest part whose closed box holds lattice point (x, y), `top` on the
// tile's border (drawn at the tile's level): the most the morph pass lets a vertex there take
// from its parents, so that a part never draws, nor drops, a vertex of a finer block than its
// own at a weight above 0 (tools/tiles/src/parts.rs, coarsest_level, the CPU side).
uint packed_coarsest_level(uvec2 parts, uint x, uint y, uint top) {
    if (on_tile_border(x, y)) {
        return top;
    }
    uvec4 l = holding_levels(parts, x, y);
    return min(min(l.x, l.y), min(l.z, l.w));
}
