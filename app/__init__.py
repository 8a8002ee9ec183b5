"""voxwarp application layer: volume I/O, scene, camera, transfer functions, renderer, CLI."""
