"""Wire field (Journal of WSCG 14, 2006): bend, twist and scale objects in a volume along
curves ("wires"), without resampling.

Modules, by role: ``wire`` (the :class:`~voxwarp.deform.wires.wire.Wire`, its keys and JSON
form), ``tables`` (its lookup tables of the mapping), ``constants`` (limits and tuning),
``build`` (:class:`~voxwarp.deform.wires.build.WireDeformer`, the attribute field build) with
its stages ``masks`` (plane masks), ``sides`` (seeds, propagation, flags) and ``seams``
(the weight's fade where the closest point jumps), ``layouts`` (the
built field and its storage layouts), ``warp``
(:class:`~voxwarp.deform.wires.warp.WireFieldWarp`: CPU reference, GLSL side, JSON) with
``bounds`` (displacement bounds for empty-space skipping), ``geometry`` (small helpers);
``curves`` (the wire's curve and its frames), ``propagation`` (nearest-seed propagation on
pyopencl or scipy), ``classify`` (the OpenCL pass of propagation and flags). ``field`` keeps
the names other code imported from the single module this was.

About this technique (Journal of WSCG 14, 2006: non-linear, non-reconstructive volume
deformation by sweeping, sections 4-9; an extension of Maya's wire deformer to volumes)
------------------------------------------------------------------------------------------
A :class:`Wire` is a *base* curve laid through an object and a *modified* copy of it
(same curve type) that the user bends, plus a twist angle θ and a scale s keyed at any
points along it. The object is *swept*: the cross-section of the object on the plane
normal to the base wire at arc-length fraction u is shown on the plane normal to the
modified wire at the same fraction u, rotated by θ(u) about the wire and scaled by s(u).
Base and modified wire may differ in length (the object is compressed or stretched along
it). The parameter of every key, table and the attribute field is that arc-length
fraction u in [0, 1] (0 = first control point), the same on both curves: this is the
paper's plane-to-plane mapping by t.

Frames. Twist needs a frame on each curve that has no twist of its own: both curves
carry rotation-minimising frames (double reflection,
:meth:`voxwarp.deform.wires.curves.Curve.frames`);
the base frame starts from ``initial_normal`` (default: the world axis least aligned
with the base tangent), the modified frame from that normal carried by the minimal
rotation between the two start tangents. So a wire that is only translated or bent in
a plane maps cross-sections without rotating them, and θ is exactly the rotation seen.

Mapping (section 6). A deformed-space point p near the modified wire at fraction u has
local coordinates ``(x, y, z) = F_m(u)^T (p - M(u))`` in the modified frame
``F_m = (N_m, B_m, T_m)``. It shows the original point
``q = C(u) + F_b(u) diag(1/s, 1/s, L_b/L_m) R_z(-θ) (x, y, z)`` near the base wire
(C the base wire's point), i.e. ``q = C(u) + A(u) (p - M(u)) = A(u) p + b(u)``. The
along-wire offset z is kept (scaled by the length ratio), so an error in u moves M and
C together along straight parts and the mapping is first-order insensitive to it.
``A`` and ``b`` are tabulated at :data:`LUT_SIZE` equally spaced fractions ("wire point
and frame lookup tables at integer t", section 7.2, 3 RGBA texels per entry) and
interpolated linearly; the CPU reference, the masks and the shader all use these same
tables. The Jacobian of the warp is A(u) (the dependence of u on p is second order;
section 6.1 carries the gradient by it).

Attribute field (section 5). Each ray sample needs to know whether it is swept, by
which wire, and its u. The field holds that per voxel of a grid ``field_scale`` times
coarser than the volume per axis (1:1, 1:8, 1:64, 1:512, 1:4096 in voxels), over the
volume's box grown to hold the modified wires' regions of influence (a bent object may
leave the original box). It is built in deformed space:

1. *Planes* (5, 7.1): one plane per ``mask_resolution`` of modified arc length, normal
   to the modified wire, each carrying a square mask of ``mask_resolution`` pixels
   covering the region of influence (a disc of ``radius``). Each pixel's point is mapped
   to the base side (the mapping above) and classified there by β (a value range of the
   volume by default; any callable on values works).
2. *Plane masks* (7.1): a 2.5D seed fill of the β pixels from a seed on each plane,
   found by searching outward from the wire (the β pixel nearest to it): a pixel joins
   when it connects to a seed within its plane or through the neighbouring planes (so an
   object that forks along the wire, like a tail fin, stays whole); holes are filled (a
   vessel's lumen, a swim bladder move with their object); then ``dilation`` pixels of
   morphological dilation; planes with no object are dropped. Only the object the wire
   runs through is swept, which solves the delineation problem of two nearby objects
   (with ``masks=False`` every β pixel in the disc is swept instead).
3. *Voxel initialisation* (5.1): where the modified wire enters a field cell, its eight
   voxels become seeds with (γ wire id, ε closest u, d distance), keeping the minimum d.
4. *Propagation*: every voxel of the region takes (γ, ε) of its nearest seed, by an
   exact Euclidean distance transform in OpenCL (:mod:`voxwarp.deform.wires.propagation`, PoCL on
   the
   CPU here, any OpenCL GPU elsewhere; scipy when no platform exists, with a warning).
   Distances are discarded. ε is then refined to the closest point of the wire
   (:data:`REFINE_STEPS` Newton steps): the nearest seed's u is off by up to a voxel
   along the wire, which a fast twist would turn into a visible rotation error.
   That is ``propagate="region"`` (the default). The paper propagates only over the
   voxels flagged by the plane masks (5.1, 7.1): ``propagate="flagged"`` first marks the
   voxels holding a set mask pixel (grown by a voxel; the end planes carried along the
   end tangents as far as step 5 reaches), then finds the nearest seed (a k-d tree)
   only for them and their neighbours (which swept samples interpolate t from), and
   keeps step 5's test on them. Same field up to nearest-seed ties; which one builds
   faster depends on the device (docs/benchmarks.md).
5. *Flags*: a voxel is swept where the mask of its plane (at ε) covers its projection;
   the rest of the field is the identity. The original place of the swept object is
   *vacated*: the same propagation from the base wires, tested against the same masks
   (turned and scaled as the sweep does), marks it, and samples landing there (unswept)
   show nothing, so the bent object leaves no copy behind. A field voxel counts when its
   footprint touches a mask (the masks grow by half a field voxel), so coarse fields
   neither cut the object's edges nor leave thin parts of it behind. Where the OpenCL
   device has double precision, steps 4-5 run as one pass on it
   (:mod:`voxwarp.deform.wires.classify`: the nearest-seed indices never leave the device,
   and the refinement and mask tests give the numpy path's bits); else in numpy.

Wire sides (not in the paper). The paper sweeps only the masked object and vacates its
original place: the field's voxels are flagged from the plane masks (section 5) and the
renderer ignores every unflagged voxel (section 6), so that place shows nothing. On real
anatomy, where tissue surrounds the swept cylinder, that reads as a hole (a crescent
where the cylinder was) and a tear (where its rim meets unmoved tissue). So
``sides="smooth"`` (the default, also for wire files without the key) moves everything
within ``radius + side_falloff`` of the modified wire, with no masks (β is not used):
``warp(p) = p + w(p) (A p + b - p)``, w = 1 inside the (scaled) radius, falling with a
smoothstep (C1) to 0 over ``side_falloff`` mm beyond it (times the end fade below);
nothing is vacated, nothing tears at the radius. The field's "swept" voxels are then the
whole tube of that reach (steps 1-2 give full discs; step 5 marks nothing vacated). The
default ``side_falloff`` is the radius or twice the wire's largest move
(:meth:`Wire.largest_move`), whichever is longer: across the fade the warp is
``p + w d`` with ``|d| <= m`` and the smoothstep's steepest slope is 1.5 / F, so det J
falls to ``1 - 1.5 m / F`` and a fade narrower than 1.5 m folds (the build warns in one
line, :meth:`Wire.side_fold_warning`). Seams: where the closest point on the wires
jumps (past a bend's radius of curvature, where the wire's normal planes cross; where two
wires' regions meet), the sweep jumps while w > 0, which would tear the map; the build
(:mod:`voxwarp.deform.wires.seams`) marks 6-neighbour voxel pairs whose wire differs or
whose closest point moves more than :data:`SEAM_STEP_VOXELS` field voxels along the wire,
and multiplies w by a smoothstep of the distance to them, over the smallest width that is
twice the weighted move within it (at most ``side_falloff``), so the map meets the
identity there continuously; wires without seams keep their weights bit for bit
(:attr:`WireFieldStats.seam_faded` counts the faded voxels). Content near a seam moves
less than the wire asks: keep the reach below the bend's radius of curvature where the
whole move matters.
``sides="rigid"`` is the paper's sweep (masks, vacated place), kept for the reproductions
(the bundled files, benchmarks and teaching code say so explicitly); with it
``vacated="rest"`` marks nothing vacated, so the place shows its unmoved content
(``"empty"``: the paper). :meth:`WireFieldWarp.vacated` tells which deformed-space points
show nothing. The Jacobian is ``I + w (A - I) + (A p + b - p) (x) grad w`` with the exact
gradient of the trilinear weight (CPU and GLSL alike), so shading is right in the fade;
the terms through t's gradient are left out, as section 6.1 does.

Wire ends (not in the paper). The rigid sweep (``ends="rigid"``) moves nothing past the
end planes and the radius: a wire that ends inside an object, or an object wider than
the radius, is cut there, and the build warns when a moving end lies inside its object.
``ends="smooth"`` (the default) blends the sweep with the identity beyond them:
``warp(p) = p + w(p) (A p + b - p)``, with w = 1 inside the radius and between the end
planes, falling smoothly (a smoothstep) to 0 over ``falloff`` mm beyond each end along
its tangent (the mapping there is the end plane's, extended) and over
:data:`RADIAL_FADE` times the radius beyond the radius. Planes beyond the ends use the
end plane's mask (with smooth sides, the fade is ``side_falloff`` instead of
:data:`RADIAL_FADE`). w is stored per field voxel (float32; the shader interpolates its
8 texels itself, as the CPU does, and takes the gradient from them). With rigid sides,
the object's place is vacated only out to the middle of the fades: past it the content
has mostly stayed and shows in place, so a fade leaves no hole; a move larger than the
fade still folds (a doubled strip), so give a falloff of at least twice the end's move.

Storage (7.2). Two layouts, chosen by ``layout``:

* ``"float"``: ``state`` uint8 per voxel (0 identity, 1 vacated, 2 + γ swept) and ``t``
  float32 (u·255, trilinearly filtered by the hardware): 5 bytes per voxel.
* ``"packed"``: the paper's 2 bytes per voxel: bit 15 the swept flag, bits 8-14 the
  wire id γ, bits 0-7 the integer t = round(255 u) (the segment of that t is in the
  wire's lookup table, :attr:`WireTables.segment_base` / ``segment_modified``); unswept
  voxels keep their γ and t so that swept neighbours can interpolate t, and the code
  ``0x7FFF`` marks a vacated voxel. The shader interpolates t itself from the 8
  neighbours of the same wire.
* ``"paper"``: the paper's own 2-byte example (section 7.2): bit 15 the swept flag, bits
  11-14 the wire id γ (16 wires), bits 7-10 the segment index of the modified curve
  holding the voxel's closest point (16 segments; the segments of
  :meth:`voxwarp.deform.wires.curves.Curve.segment_of`, found through the wire's table of
  curve parameters), bits 0-6 the integer t within that segment (128 steps). The t
  steps are equally spaced in arc length within the segment: with ``u_s`` the fraction
  where segment s starts, ``u = u_s + (t / 127) (u_{s+1} - u_s)``, so every code maps
  exactly to the fraction u that indexes the lookup tables (``WireField.segments``
  holds ``u_s`` per wire, in table units; the shader reads it from a 17-texel row per
  wire). The paper caches wire points and frames "at each integer t"; here those are
  the same tables, read at that u. Neighbours are interpolated in u, never in the
  per-segment t (two neighbours in different segments would otherwise mix unrelated t
  values). Unswept voxels keep their wire, segment and t (flag 0), and ``0x7FFF`` marks
  a vacated voxel, as in the packed layout (an unswept code that would collide becomes
  t = 126). At most :data:`PAPER_MAX_WIRES` wires of at most
  :data:`PAPER_MAX_SEGMENTS` segments each.

Mask memory (7.1). The paper counts ``sum_p a(p) s / 8`` bytes per wire: one bit per
mask pixel, ``a(p)`` the area of plane p and ``s`` the pixels per unit area. Here each
kept plane (planes without object are dropped, as in the paper) is a square of K x K
pixels of ``mask_resolution`` mm: ``a(p) = (K mask_resolution)^2`` mm^2 and
``s = 1 / mask_resolution^2`` pixels per mm^2, so a wire needs ``kept planes x K^2 / 8``
bytes (:attr:`WireFieldStats.mask_bytes`).

Rendering: per sample one field fetch decides identity / vacated / swept; a swept
sample adds the t fetch (8 in the packed and paper layouts; the paper layout turns each
into its table coordinate through two entries of a uniform array of segment starts) and
3 fetches of the tiny lookup table (``q = A p + b``, A and b linear in t).
:meth:`WireFieldWarp.displacement_range` bounds ``warp(p) - p`` per box from the field,
so the raycaster keeps skipping empty space through the deformed volume.

Limits: at most :data:`MAX_WIRES` (128) wires per field (the packed layout's 7-bit id);
16 wires of at most 16 segments with ``layout="paper"``.
"""
