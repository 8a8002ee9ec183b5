// Mass-spring block atlas (see deform/elements/massspring_gpu.py): the (NX, NY, NZ) element grid
// is cut into blocks of SX x SY x SZ elements, one fragment each; the (BX, BY, BZ)
// block grid is stored as z-slices tiled TX per row in 2D textures (one texture per
// element of a block); slice k is the BX x BY tile at column k % TX, row k / TX. All
// are compile-time constants (massspring_config.glsl, generated per solver), so the
// divisions below fold into multiplications.

// block (I, J, K) -> atlas texel
ivec2 ms_texel(ivec3 b) {
    return ivec2(b.x + (b.z % TX) * BX, b.y + (b.z / TX) * BY);
}

// atlas texel -> block (I, J, K); only meaningful inside the BZ used tiles
ivec3 ms_block(ivec2 t) {
    ivec2 tile = t / ivec2(BX, BY);
    return ivec3(t - tile * ivec2(BX, BY), tile.y * TX + tile.x);
}
