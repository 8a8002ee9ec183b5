// Mass-spring element atlas (see deform/massspring_gpu.py): the (NX, NY, NZ) element
// grid is stored as z-slices tiled TX per row in a 2D texture; slice k is the NX x NY
// tile at column k % TX, row k / TX. NX, NY, NZ, TX are compile-time constants
// (massspring_config.glsl, generated per solver), so the divisions below are cheap.

// element (i, j, k) -> atlas texel
ivec2 ms_texel(ivec3 e) {
    return ivec2(e.x + (e.z % TX) * NX, e.y + (e.z / TX) * NY);
}

// atlas texel -> element (i, j, k); only meaningful inside the NZ used tiles
ivec3 ms_element(ivec2 t) {
    ivec2 tile = t / ivec2(NX, NY);
    return ivec3(t - tile * ivec2(NX, NY), tile.y * TX + tile.x);
}

bool ms_inside(ivec3 e) {
    return all(greaterThanEqual(e, ivec3(0))) && all(lessThan(e, ivec3(NX, NY, NZ)));
}
