"""Wire field (Journal of WSCG 14, 2006): curves laid through an object, bent, twisted and
scaled; an attribute field built by distance propagation maps each sample back to the base
wire.

Modules: ``curves`` (the wire's curve and its frames), ``propagation`` (nearest-seed
propagation on pyopencl or scipy), ``classify`` (which side of a wire's planes a voxel is),
``field`` (the wire, the attribute field build and its warp).
"""
