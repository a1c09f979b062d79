// The vertex hierarchy of a tile's meshes (tools/tiles/src/compact.rs, `parents`): every grid
// point but the tile's corners lies midway between two parents of a coarser scale. Shared by
// the morph pass, which places a vertex from its parents, and the compact levels' decoder,
// which predicts a vertex's height from them.

// The parents (p, q) of grid point (x, y) of scale 2^k (k < 8): an edge's midpoint has the
// edge's ends; a cell's centre the diagonal through its parent cell's centre (the tile's
// centre, whose cell has no parent: the north-west to south-east one).
void parents_of(uint x, uint y, uint k, out uvec2 p, out uvec2 q) {
    uint s = 1u << k;
    bool ox = ((x >> k) & 1u) == 1u;
    bool oy = ((y >> k) & 1u) == 1u;
    if (ox && oy) {
        bool dx = s == 128u || (((x + s) >> (k + 1u)) & 1u) == 1u;
        bool dy = s == 128u || (((y + s) >> (k + 1u)) & 1u) == 1u;
        p = uvec2(dx ? x + s : x - s, dy ? y + s : y - s);
        q = uvec2(dx ? x - s : x + s, dy ? y - s : y + s);
    } else if (ox) {
        p = uvec2(x - s, y);
        q = uvec2(x + s, y);
    } else {
        p = uvec2(x, y - s);
        q = uvec2(x, y + s);
    }
}
