"""Deterministic synthetic phantoms in Hounsfield-like units, plus the bundled real scans.

Every generator has the signature ``fn(shape=(nx, ny, nz), seed=0) -> SampleData`` and
returns an ``int16`` array indexed ``data[i, j, k]`` (``i`` along x, ``j`` along y, ``k``
along z). Values follow the CT scale (air -1000, fat about -100, water and soft tissue
0 to 60, bone 700 to 1800) so the CT transfer-function presets apply directly. The
geometry is fixed and defined in normalised coordinates, so any shape works; the field
of view in millimetres is fixed too, so the spacing is ``fov / shape`` and a phantom keeps
its physical proportions whatever the shape. The seed only drives the additive Gaussian
noise (standard deviation :data:`NOISE_STD` HU).

This module imports nothing from the rest of the project (numpy, scipy and the standard
library only): it sits below every other layer.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources

import numpy as np

# scipy (ndimage, interpolate, spatial) loads inside the generators that use it, so
# loading a bundled scan (e.g. ``stent``) does not pay for its import.

#: Standard deviation of the additive noise, in HU.
NOISE_STD = 10.0
#: Most voxels along one axis of a generated phantom (the GPU's usual 3D texture limit).
MAX_SAMPLE_AXIS = 2048
#: Most voxels of a generated phantom (400³; made with float32 temporaries, so its peak
#: memory is many times the int16 result).
MAX_SAMPLE_VOXELS = 1 << 26
#: Field of view (x, y, z) of :func:`fish`, mm (0.5 mm voxels at the default shape).
FISH_FOV_MM = (96.0, 48.0, 40.0)
#: Field of view (x, y, z) of :func:`tubes`, mm (0.5 mm voxels at the default shape).
TUBES_FOV_MM = (64.0, 64.0, 48.0)
#: Field of view (x, y, z) of :func:`head`, mm (1.5 mm voxels at the default shape).
HEAD_FOV_MM = (192.0, 192.0, 192.0)


@dataclass(frozen=True)
class SampleData:
    """A sample volume with its metadata.

    ``data`` is indexed ``data[i, j, k]`` with ``i`` along x; ``spacing`` is the voxel
    size ``(sx, sy, sz)`` in mm; ``units`` is ``"HU"`` for the phantoms and ``""`` when
    the values have no physical unit; ``origin`` is the position in mm of the centre of
    voxel ``(0, 0, 0)``; ``axes`` is the patient axis code of the array's axes (e.g.
    ``"RAS"``: i grows towards the patient's right, j anterior, k superior) for real
    scans whose orientation is known, ``""`` for phantoms.
    """

    data: np.ndarray
    spacing: tuple[float, float, float]
    units: str
    description: str
    source: str
    license: str
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axes: str = ""


# --------------------------------------------------------------------------- helpers
def _check_shape(shape: tuple[int, int, int]) -> tuple[int, int, int]:
    shp = tuple(int(n) for n in shape)
    if len(shp) != 3 or min(shp) < 1:
        raise ValueError(f"shape must be three positive integers (nx, ny, nz); got {shape!r}")
    if max(shp) > MAX_SAMPLE_AXIS or math.prod(shp) > MAX_SAMPLE_VOXELS:
        raise ValueError(
            f"shape {shp} is over the phantom limits ({MAX_SAMPLE_AXIS} voxels per axis,"
            f" {MAX_SAMPLE_VOXELS:,} voxels in all: a phantom needs tens of bytes per voxel"
            " while it is made); give a smaller shape, e.g. (256, 256, 256)"
        )
    return shp  # type: ignore[return-value]


def _spacing(fov: tuple[float, float, float], shape: tuple[int, int, int]) -> tuple:
    return tuple(float(f) / n for f, n in zip(fov, shape, strict=True))


def _finish(vol: np.ndarray, seed: int, blur: float = 0.0) -> np.ndarray:
    """Optional partial-volume blur (sigma in voxels), seeded noise, round to int16."""
    if blur > 0:
        from scipy import ndimage

        vol = ndimage.gaussian_filter(vol, blur, mode="nearest", truncate=3.0)
    rng = np.random.default_rng(seed)
    vol += rng.standard_normal(vol.shape, dtype=np.float32) * np.float32(NOISE_STD)
    np.clip(vol, -1024, 3071, out=vol)
    return np.rint(vol).astype(np.int16)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


# --------------------------------------------------------------------------- fish
# The fish is built in "fish units": x in [0, 1] along the length of the box (head at
# small x, tail at large x), y and z centred on the box and scaled by the same factor
# (FISH_FOV_MM[0] mm per unit at any shape), so y spans +-0.25 and z spans +-0.208.
# z is dorsal (up), y is lateral: the side view is a projection along y.

# half-height of the body (fish units) at control points along x; PCHIP in between
_BODY_X = np.array(
    [0.03, 0.0335, 0.042, 0.06, 0.09, 0.13, 0.19, 0.28, 0.38, 0.48, 0.58, 0.68, 0.76, 0.82, 0.85]
)
_BODY_X = np.append(_BODY_X, 0.87)
_BODY_H = np.array(
    [0.0, 0.024, 0.043, 0.064, 0.082, 0.095, 0.108, 0.12, 0.124, 0.114, 0.092, 0.064, 0.043, 0.034]
)
_BODY_H = np.append(_BODY_H, [0.03, 0.0])
_BODY_WR = (  # half-width / half-height ratio along the body
    np.array([0.03, 0.12, 0.25, 0.5, 0.8, 0.87]),
    np.array([0.72, 0.66, 0.55, 0.5, 0.42, 0.42]),
)
_SPINE_X0, _SPINE_X1 = 0.215, 0.86  # first and last vertebra (fish units)
_VERT_PERIOD_VOX = 5.5  # aimed-at vertebra period in voxels along x
_VERT_FILL = 0.62  # fraction of a period that is centrum (the rest is disc)


def _fish_profiles(x: np.ndarray) -> dict[str, np.ndarray]:
    """1D profiles along the fish (x in fish units): half-height, half-width, spine, centre."""
    from scipy.interpolate import PchipInterpolator

    h = np.clip(PchipInterpolator(_BODY_X, _BODY_H, extrapolate=False)(x), 0.0, None)
    h = np.nan_to_num(h, nan=0.0)
    w = h * np.interp(x, *_BODY_WR)
    s = _spine_z(x)
    ds = _spine_dz(x)
    zb = s - 0.25 * h
    return {"h": h, "w": w, "s": s, "ds": ds, "zb": zb}


def _spine_z(x: np.ndarray | float) -> np.ndarray:
    """Height (fish units) of the gently curved spine line at length coordinate x."""
    return -0.015 + 0.02 * np.sin(np.pi * (np.asarray(x) - 0.12) / 0.8)


def _spine_dz(x: np.ndarray | float) -> np.ndarray:
    return 0.02 * np.pi / 0.8 * np.cos(np.pi * (np.asarray(x) - 0.12) / 0.8)


def fish_spine(shape: tuple[int, int, int] = (192, 96, 80), n: int = 64) -> np.ndarray:
    """Points along the spine of :func:`fish` for ``shape``, in voxel index coordinates.

    Returns an ``(n, 3)`` float array of continuous indices ``(i, j, k)``, from the first
    vertebra (behind the skull) to the last one (in the tail), handy as a control wire
    for bending the fish. Multiply by the ``spacing`` of the fish for millimetres.
    """
    nx, ny, nz = _check_shape(shape)
    x = np.linspace(_SPINE_X0, _SPINE_X1, int(n))
    z = _spine_z(x)
    fz = FISH_FOV_MM[2] / FISH_FOV_MM[0]
    i = x * nx - 0.5
    j = np.full_like(x, 0.5 * ny - 0.5)
    k = (z / fz + 0.5) * nz - 0.5
    return np.stack([i, j, k], axis=1)


def _fish_grid(shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    nx, ny, nz = shape
    x = ((np.arange(nx) + 0.5) / nx).astype(np.float32)
    y = (((np.arange(ny) + 0.5) / ny - 0.5) * FISH_FOV_MM[1] / FISH_FOV_MM[0]).astype(np.float32)
    z = (((np.arange(nz) + 0.5) / nz - 0.5) * FISH_FOV_MM[2] / FISH_FOV_MM[0]).astype(np.float32)
    return x, y, z


def _fin_rays(u: np.ndarray, period: float) -> np.ndarray:
    """Fin density (HU): membrane ~110 with denser rays ~190 every ``period``."""
    return (150.0 + 45.0 * np.cos(2.0 * np.pi * u / period)).astype(np.float32)


def _paired_fin(
    vol: np.ndarray,
    grid: tuple[np.ndarray, np.ndarray, np.ndarray],
    root: tuple[float, float, float],
    direction: tuple[float, float, float],
    length: float,
    width: float,
    thick: float,
    ray_period: float,
) -> None:
    """Paint a thin leaf-shaped fin rooted at ``root`` pointing along ``direction``."""
    x, y, z = grid
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    n = np.cross(d, [1.0, 0.0, 0.0])
    n /= np.linalg.norm(n)
    b = np.cross(n, d)
    r0 = np.asarray(root, float)
    reach = length + width + thick
    sl = []
    for ax, c in zip((x, y, z), r0, strict=True):
        sel = np.nonzero(np.abs(ax - c) <= reach)[0]
        if sel.size == 0:
            return
        sl.append(slice(int(sel[0]), int(sel[-1]) + 1))
    px = x[sl[0], None, None] - r0[0]
    py = y[None, sl[1], None] - r0[1]
    pz = z[None, None, sl[2]] - r0[2]
    a = px * d[0] + py * d[1] + pz * d[2]
    c = px * b[0] + py * b[1] + pz * b[2]
    t = px * n[0] + py * n[1] + pz * n[2]
    al = np.clip(a / length, 0.0, 1.0)
    half_w = width * np.sqrt(np.clip(al * (1.0 - al) ** 0.6, 0.0, None)) * 1.6
    m = (a >= 0) & (a <= length) & (np.abs(c) <= half_w) & (np.abs(t) <= thick)
    sub = vol[sl[0], sl[1], sl[2]]
    rays = _fin_rays(np.broadcast_to(c, m.shape), ray_period)
    sub[m] = rays[m]


def fish(shape: tuple[int, int, int] = (192, 96, 80), seed: int = 0) -> SampleData:
    """A carp-like fish lying along x (head at low x, dorsal side towards +z), in HU.

    Soft-tissue body (muscle ~50 HU, skin ~80, viscera ~30, belly fat ~-90) with a
    head (brain case with a bony shell, gill covers, eyes in bony sockets with a lens),
    fins of ~100-200 HU with rays (forked tail fin, dorsal, anal, pectoral and pelvic
    fins), a gently curved spine of separate hourglass-shaped vertebrae (~1400 HU,
    separated by ~90 HU discs) with neural and haemal spines, ribs hanging from the
    abdominal vertebrae on both sides, and a two-lobed air-filled swim bladder
    (-800 HU) below the spine. Background is air (-1000 HU). The field of view is
    :data:`FISH_FOV_MM`, so the spacing is 0.5 mm at the default shape.
    :func:`fish_spine` gives the spine line in voxel coordinates.
    """
    shape = _check_shape(shape)
    nx, ny, nz = shape
    x, y, z = _fish_grid(shape)
    vox = max(1.0 / nx, FISH_FOV_MM[1] / FISH_FOV_MM[0] / ny, FISH_FOV_MM[2] / FISH_FOV_MM[0] / nz)
    p = {k: v.astype(np.float32) for k, v in _fish_profiles(x.astype(np.float64)).items()}
    h, w, s, ds, zb = p["h"], p["w"], p["s"], p["ds"], p["zb"]
    X = x[:, None, None]
    Y = y[None, :, None]
    Z = z[None, None, :]
    H = h[:, None, None]
    W = w[:, None, None]
    S = s[:, None, None]
    ZB = zb[:, None, None]
    eps = np.float32(1e-6)

    vol = np.full(shape, -1000.0, dtype=np.float32)
    fin_t = max(0.0045, 0.9 * vox)
    ray_p = max(0.0156, 2.6 * vox)

    # ---- median fins (in the plane y = 0), painted first so the body covers their roots
    ym = np.abs(Y) <= fin_t
    top = ZB + H
    # dorsal fin: long base, tall leading rays
    xd0, xd1 = 0.38, 0.66
    td = np.clip((X - xd0) / (xd1 - xd0), 0.0, 1.0)
    hd = (0.018 + 0.07 * np.exp(-td / 0.16)) * _smoothstep(0.0, 0.02, X - xd0)
    dz = Z - top
    m = ym & (X >= xd0) & (X <= xd1) & (dz >= -0.02) & (dz <= hd * (1.0 - 0.35 * td))
    vol = np.where(m, _fin_rays(X - 0.45 * dz, ray_p), vol)
    # anal fin
    xa0, xa1 = 0.655, 0.75
    ta = np.clip((X - xa0) / (xa1 - xa0), 0.0, 1.0)
    ha = (0.018 + 0.05 * (1.0 - ta) ** 0.8) * _smoothstep(0.0, 0.012, X - xa0)
    dz = (ZB - H) - Z
    m = ym & (X >= xa0) & (X <= xa1) & (dz >= -0.02) & (dz <= ha)
    vol = np.where(m, _fin_rays(X - 0.45 * dz, ray_p), vol)
    # forked caudal fin: a fan from the caudal peduncle, longer at the two lobes
    x_ped = 0.80
    z_ped = float(_spine_z(x_ped))
    dxc = X - np.float32(x_ped)
    dzc = Z - np.float32(z_ped)
    r = np.sqrt(dxc * dxc + dzc * dzc)
    phi = np.arctan2(dzc, np.maximum(dxc, eps))
    phimax = np.float32(np.deg2rad(46.0))
    aphi = np.abs(phi) / phimax
    reach = 0.11 + 0.095 * aphi**1.6 - 0.02 * np.clip((aphi - 0.85) / 0.15, 0.0, 1.0) ** 2
    m = ym & (dxc >= 0) & (aphi <= 1.0) & (r <= reach)
    vol = np.where(m, _fin_rays(phi * 0.1, np.deg2rad(7.0) * 0.1), vol)

    # ---- body: elliptical cross-sections, tapered profile
    rho2 = (Y / np.maximum(W, eps)) ** 2 + ((Z - ZB) / np.maximum(H, eps)) ** 2
    body = (rho2 <= 1.0) & (H > 0)
    rho = np.sqrt(rho2)
    skin_frac = np.float32(1.3 * vox) / np.maximum(np.minimum(H, W), eps)
    vol[body] = 50.0
    vol[body & (rho > 1.0 - skin_frac)] = 80.0
    deep = body & (rho < 1.0 - 2.3 * skin_frac)  # >= 3 voxels under the skin: bone allowed

    # ---- paired fins (pectoral behind the head, pelvic under the belly)
    pr = _fish_profiles(np.array([0.205, 0.47]))
    for side in (-1.0, 1.0):
        _paired_fin(
            vol,
            (x, y, z),
            root=(0.2, side * 0.75 * pr["w"][0], pr["zb"][0] - 0.55 * pr["h"][0]),
            direction=(0.8, side * 0.5, -0.32),
            length=0.115,
            width=0.034,
            thick=fin_t,
            ray_period=ray_p,
        )
        _paired_fin(
            vol,
            (x, y, z),
            root=(0.47, side * 0.35 * pr["w"][1], pr["zb"][1] - 0.85 * pr["h"][1]),
            direction=(0.8, side * 0.22, -0.55),
            length=0.075,
            width=0.022,
            thick=fin_t,
            ray_period=ray_p,
        )

    # ---- spine frame: along-spine coordinate q, perpendicular offsets (y, dzp), radius
    DS = ds[:, None, None]
    dzs = Z - S
    q = X + dzs * (DS / (1.0 + DS * DS))
    dzp = dzs / np.sqrt(1.0 + DS * DS)
    rperp = np.sqrt(Y * Y + dzp * dzp)
    rc = np.maximum(0.1 * H + 0.002, max(0.006, 1.2 * vox))
    n_vert = int(np.clip(round((_SPINE_X1 - _SPINE_X0) * nx / _VERT_PERIOD_VOX), 6, 40))
    period = (_SPINE_X1 - _SPINE_X0) / n_vert

    def vert_phase(qq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = (qq - np.float32(_SPINE_X0)) / np.float32(period)
        idx = np.floor(f)
        ok = (idx >= 0) & (idx < n_vert)
        return (f - idx - 0.5) * np.float32(period), ok  # signed distance to centre, valid

    # ---- body cavity (viscera, belly fat) and the rib ellipse around it
    env = np.sqrt(np.clip(1.0 - ((X - 0.43) / 0.2) ** 4, 0.0, 1.0))
    cav_top = S - rc
    cav_bot = ZB - 0.75 * H
    zc = 0.5 * (cav_top + cav_bot)
    bc = 0.5 * (cav_top - cav_bot) * env
    ac = 0.62 * W * env
    e_cav = (Y / np.maximum(ac, eps)) ** 2 + ((Z - zc) / np.maximum(bc, eps)) ** 2
    cavity = body & (e_cav <= 1.0) & (env > 0)
    vol[cavity] = 30.0
    vol[cavity & (Z < zc - 0.45 * bc)] = -90.0

    # ---- swim bladder: anterior round lobe and a longer, tapered posterior lobe
    def lobe(xc: float, a: float, b: float, c: float, taper: float) -> np.ndarray:
        zc_l = float(_spine_z(xc)) - float(0.1 * _fish_profiles(np.array([xc]))["h"][0]) - 0.011
        zc_l -= c
        scale = 1.0 - taper * np.clip((X - xc) / a, 0.0, 1.0)
        return ((X - xc) / a) ** 2 + (Y / (b * scale)) ** 2 + ((Z - zc_l) / (c * scale)) ** 2 <= 1

    bladder = lobe(0.325, 0.06, 0.03, 0.038, 0.0) | lobe(0.455, 0.085, 0.026, 0.032, 0.55)
    vol[bladder & body] = -800.0

    # ---- head: brain case with a bony shell, eyes in bony sockets, gill covers
    xbr = 0.15
    zbr = float(_spine_z(xbr)) + 0.01
    shell_t = max(0.0055, 1.1 * vox)
    ebr = np.sqrt(((X - xbr) / 0.055) ** 2 + (Y / 0.024) ** 2 + ((Z - zbr) / 0.028) ** 2)
    vol[ebr <= 1.0 + shell_t / 0.028] = 900.0
    vol[ebr <= 1.0] = 35.0
    # gill cover (opercle): a curved bony band just under the skin along its hind edge
    zrel = (Z - ZB) / np.maximum(H, eps)
    x_edge = 0.222 - 0.03 * zrel * zrel
    band = (X < x_edge) & (X > x_edge - max(0.012, 2.2 * vox))
    op = deep & band & (rho > 0.62) & (rho < 0.62 + 1.4 * skin_frac)
    vol[op & (zrel > -0.8) & (zrel < 0.62)] = 750.0
    # eyes: vitreous body with a dense lens, bulging from the head, in a bony cup
    xe = 0.085
    pe = _fish_profiles(np.array([xe]))
    re = 0.017
    ze = float(pe["zb"][0] + 0.35 * pe["h"][0])
    ye = float(pe["w"][0] - 0.5 * re)
    for side in (-1.0, 1.0):
        de = np.sqrt((X - xe) ** 2 + (Y - side * ye) ** 2 + (Z - ze) ** 2)
        cup = (de > re) & (de <= re + max(0.0045, 1.0 * vox)) & (side * Y < ye - 0.25 * re)
        vol[cup & deep] = 800.0
        vol[de <= re] = 10.0
        dl = np.sqrt((X - xe) ** 2 + (Y - side * (ye + 0.5 * re)) ** 2 + (Z - ze) ** 2)
        vol[dl <= 0.4 * re] = 170.0

    # ---- vertebrae: hourglass centra (ring ends, solid waist), discs in between
    along, ok = vert_phase(q)
    half = np.float32(0.5 * _VERT_FILL * period)
    in_cyl = ok & (rperp <= rc)
    vol[in_cyl] = 90.0  # intervertebral discs / notochord
    centrum = in_cyl & (np.abs(along) <= half)
    core = rperp < 0.72 * rc * (np.abs(along) / half) ** 1.5
    vol[centrum] = np.where(core, 160.0, 1400.0)[centrum]

    # ---- neural spines (up, raked back), haemal spines (down, tail half), ribs
    rod = max(0.004, 0.75 * vox)
    rake = np.float32(math.tan(math.radians(35.0)))
    hgt = np.abs(dzp)
    a_rod, ok_rod = vert_phase(q - hgt * rake)
    thin = ok_rod & (np.abs(a_rod) <= rod)
    up = (dzp > 0.6 * rc) & (dzp < 0.72 * (ZB + H - S))
    arch = np.abs(np.abs(Y) - 0.5 * rc) <= rod
    neural = thin & up & np.where(dzp < 1.6 * rc, arch, np.abs(Y) <= rod)
    down = (dzp < -0.6 * rc) & (-dzp < 0.7 * (S - ZB + H)) & (X > 0.6)
    haemal = thin & down & np.where(-dzp < 1.6 * rc, arch, np.abs(Y) <= rod)
    vol[(neural | haemal) & deep] = 1000.0
    # ribs: arcs of an ellipse through the spine around the cavity, raked back
    ar = 1.13 * np.maximum(ac, eps)
    br = np.maximum(S - zc, eps)
    a_rib, ok_rib = vert_phase(q - np.maximum(S - Z, 0.0) * np.float32(math.tan(math.radians(25))))
    ell = np.sqrt((Y / ar) ** 2 + ((Z - zc) / br) ** 2)
    rib = (
        ok_rib
        & (np.abs(a_rib) <= rod)
        & (np.abs(ell - 1.0) * np.minimum(ar, br) <= rod)
        & (Z < S - 0.5 * rc)
        & (Z > zc - 0.7 * br)
        & (X > 0.25)
        & (X < 0.6)
        & (env > 0.3)
    )
    vol[rib & deep] = 1100.0

    data = _finish(vol, seed, blur=0.4)
    return SampleData(
        data=data,
        spacing=_spacing(FISH_FOV_MM, shape),
        units="HU",
        description=(
            "Synthetic carp-like fish along x (dorsal towards +z): soft-tissue body, head"
            " with brain case, gill covers and eye sockets, fins with rays, separate"
            " vertebrae on a curved spine with neural/haemal spines and ribs, two-lobed"
            " air-filled swim bladder."
        ),
        source=f"voxwarp.sample_volumes.generators.fish(shape={shape}, seed={seed})",
        license="BSD-3-Clause (voxwarp)",
    )


# --------------------------------------------------------------------------- tubes
_TUBE_R_OUT = 2.5  # mm: outer radius of every tube (5 voxels at the default shape)
_TUBE_R_IN = 1.5  # mm: lumen radius (a 1 mm = 2 voxel wall)
_TUBE_WALL_HU = (300.0, 260.0, 360.0, 400.0, 330.0)
_TUBE_LUMEN_HU = 0.0
_TUBE_BACKGROUND_HU = -100.0


def _tube_curves(n: int = 4000) -> list[np.ndarray]:
    """Centre lines (mm, in the :data:`TUBES_FOV_MM` box) of the five tubes, densely sampled.

    1 and 2 run along x side by side, nearly touching around x = 20 mm; 3 runs along y
    and crosses over 1 and 2; 4 climbs along z past 2 and 3; 5 is a hairpin whose two
    limbs run close to each other and under 3.
    """
    t = np.linspace(0.0, 1.0, n)
    curves = []
    # 1: along x, gentle bends in y and z
    x1 = -4.0 + 72.0 * t
    y1 = 22.0 + 5.0 * np.cos(2 * np.pi * (x1 - 20.0) / 60.0)
    z1 = 20.0 + 4.0 * np.cos(2 * np.pi * (x1 - 20.0) / 64.0)
    curves.append(np.stack([x1, y1, z1], 1))
    # 2: offset of 1 in y, closest (gap _GAP12) at x = 20 where 1 has zero slope
    gap = 2 * _TUBE_R_OUT + _GAP12 + 10.0 * (1.0 - np.exp(-(((x1 - 20.0) / 12.0) ** 2)))
    curves.append(np.stack([x1, y1 + gap, z1], 1))
    # 3: along y, arching over 1 and 2 near x = 46 mm
    y3 = -4.0 + 72.0 * t
    x3 = 46.0 + 4.0 * np.sin(2 * np.pi * (y3 - 10.0) / 90.0)
    z3 = _Z3 + 3.0 * np.cos(2 * np.pi * (y3 - 25.0) / 70.0)
    curves.append(np.stack([x3, y3, z3], 1))
    # 4: climbs along z, bending in x and y
    z4 = -4.0 + 56.0 * t
    x4 = 28.0 + 6.0 * np.sin(np.pi * z4 / 48.0)
    y4 = _Y4 - 6.0 * np.cos(np.pi * z4 / 40.0)
    curves.append(np.stack([x4, y4, z4], 1))
    # 5: hairpin in a tilted plane: two limbs along x joined by a half circle
    half = (2 * _TUBE_R_OUT + _GAP5) / 2.0
    s = t * (2 * 40.0 + np.pi * half)  # arc length: limb, bend, limb
    lim = 40.0
    u = np.where(s < lim, -lim + s, np.where(s < lim + np.pi * half, 0.0, s - lim - np.pi * half))
    ang = np.clip((s - lim) / half, 0.0, np.pi)
    a = np.where(s < lim, u, np.where(s < lim + np.pi * half, half * np.sin(ang), -u))
    b = np.where(s < lim, -half, np.where(s < lim + np.pi * half, -half * np.cos(ang), half))
    x5 = 54.0 + a
    y5 = _Y5 + b * 0.8
    z5 = _Z5 + b * 0.6 + 0.05 * a
    curves.append(np.stack([x5, y5, z5], 1))
    return curves


# closest approaches (mm) were tuned with these: 1-2 0.7, 1-3 1.06, 2-3 1.42, 2-4 1.12,
# 4-5 1.25 and the two limbs of 5: 1.0 (0.5 mm voxels at the default shape)
_GAP12 = 0.7
_Z3 = 20.3
_Y4 = 42.0
_GAP5 = 1.0
_Y5 = 55.5
_Z5 = 34.0


def tubes(shape: tuple[int, int, int] = (128, 128, 96), seed: int = 0) -> SampleData:
    """Five bent tubes that run close to each other: the delineation problem, in HU.

    Hollow tubes (outer radius 2.5 mm, wall 1 mm of 260-400 HU, lumen ~0 HU) in fat
    (-100 HU) follow smooth 3D curves: two run side by side with a 0.7 mm gap, one
    arches over both (1.1 and 1.4 mm), one climbs past two others (1.1 and 1.25 mm),
    and one is a hairpin whose limbs are 1 mm apart. With the field of view
    :data:`TUBES_FOV_MM` the voxels are 0.5 mm at the default shape, so the closest
    gaps are 1.4-2.8 voxels. Voxels are anti-aliased from the exact distance to
    densely sampled centre lines (partial-volume edges), computed in chunks over z.
    """
    shape = _check_shape(shape)
    nz = shape[2]
    sp = np.asarray(_spacing(TUBES_FOV_MM, shape))
    vox = float(sp.max())
    curves = _tube_curves(max(4000, int(4 * 72.0 / float(sp.min()))))
    bound = _TUBE_R_OUT + vox
    best = np.full(shape, np.inf, dtype=np.float32)  # distance to the closest centre line
    wall = np.full(shape, _TUBE_BACKGROUND_HU, dtype=np.float32)  # that tube's wall HU
    step = max(4, int(np.ceil(2 * bound / sp[2])))  # slabs of about one tube diameter
    from scipy.spatial import cKDTree

    for curve, hu in zip(curves, _TUBE_WALL_HU, strict=True):
        tree = cKDTree(curve)
        for k0 in range(0, nz, step):
            k1 = min(nz, k0 + step)
            z_lo, z_hi = k0 * sp[2], k1 * sp[2]
            near = curve[(curve[:, 2] > z_lo - bound) & (curve[:, 2] < z_hi + bound)]
            if len(near) == 0:
                continue
            lo = np.maximum(np.floor((near.min(0) - bound) / sp).astype(int), 0)
            hi = np.minimum(np.ceil((near.max(0) + bound) / sp).astype(int) + 1, shape)
            if hi[0] <= lo[0] or hi[1] <= lo[1]:
                continue
            sub = (slice(lo[0], hi[0]), slice(lo[1], hi[1]), slice(k0, k1))
            axes = [(np.arange(lo[a], hi[a]) + 0.5) * sp[a] for a in (0, 1)]
            axes.append((np.arange(k0, k1) + 0.5) * sp[2])
            pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            d, _ = tree.query(pts, distance_upper_bound=bound, workers=-1)
            d = d.reshape(hi[0] - lo[0], hi[1] - lo[1], k1 - k0).astype(np.float32)
            closer = d < best[sub]
            best[sub] = np.where(closer, d, best[sub])
            wall[sub] = np.where(closer, np.float32(hu), wall[sub])
    w_wall = np.clip((_TUBE_R_OUT - best) / vox + 0.5, 0.0, 1.0)
    w_lumen = np.clip((_TUBE_R_IN - best) / vox + 0.5, 0.0, 1.0)
    vol = _TUBE_BACKGROUND_HU + w_wall * (wall - _TUBE_BACKGROUND_HU)
    vol += w_lumen * (_TUBE_LUMEN_HU - wall)
    data = _finish(vol, seed)
    return SampleData(
        data=data,
        spacing=tuple(float(v) for v in sp),
        units="HU",
        description=(
            "Five hollow bent tubes (walls 260-400 HU, lumen 0 HU) in fat (-100 HU) that"
            " nearly touch each other (gaps 0.7-1.4 mm = 1.4-2.8 voxels at the default"
            " shape): the delineation problem."
        ),
        source=f"voxwarp.sample_volumes.generators.tubes(shape={shape}, seed={seed})",
        license="BSD-3-Clause (voxwarp)",
    )


# --------------------------------------------------------------------------- head
# 3D Shepp-Logan-like ellipsoids in normalised coordinates (-1..1 over the field of
# view): value added (HU), semi-axes (a, b, c), centre (x0, y0, z0), rotation about z
# (degrees). y is anterior-posterior, z is superior-inferior. The first row is the
# scalp, the next two the skull (outer minus inner table) and brain, after the
# modified Shepp-Logan phantom of Toft (1996) / Yu and Wang, with HU values.
_HEAD_ELLIPSOIDS = (
    # add HU, (a, b, c), (x0, y0, z0), phi
    (1040.0, (0.72, 0.95, 0.84), (0.0, 0.0, 0.0), 0.0),  # scalp / soft tissue: 40 HU
    (960.0, (0.69, 0.92, 0.81), (0.0, 0.0, 0.0), 0.0),  # skull: 1000 HU
    (-960.0, (0.6624, 0.874, 0.78), (0.0, -0.0184, 0.0), 0.0),  # brain: 40 HU
    (-30.0, (0.11, 0.31, 0.22), (0.22, 0.0, 0.0), -18.0),  # right ventricle: 10 HU
    (-30.0, (0.16, 0.41, 0.28), (-0.22, 0.0, 0.0), 18.0),  # left ventricle: 10 HU
    (8.0, (0.21, 0.25, 0.41), (0.0, 0.35, -0.15), 0.0),  # grey-matter region: 48 HU
    (30.0, (0.046, 0.046, 0.05), (0.0, 0.1, 0.25), 0.0),  # lesion: 70 HU
    (30.0, (0.046, 0.046, 0.05), (0.0, -0.1, 0.25), 0.0),  # lesion: 70 HU
    (25.0, (0.046, 0.023, 0.05), (-0.08, -0.605, 0.0), 0.0),  # small lesion: 65 HU
    (25.0, (0.023, 0.023, 0.02), (0.0, -0.606, 0.0), 0.0),  # small lesion: 65 HU
    (25.0, (0.023, 0.046, 0.02), (0.06, -0.605, 0.0), 0.0),  # small lesion: 65 HU
)


def head(shape: tuple[int, int, int] = (128, 128, 128), seed: int = 0) -> SampleData:
    """A 3D Shepp-Logan-like head phantom in HU.

    Scalp (40 HU) around a skull shell (1000 HU) enclosing the brain (40 HU) with two
    tilted ventricles (10 HU), a grey-matter region (48 HU), two lesions (70 HU) and
    three small lesions (65 HU); air (-1000 HU) outside. The ellipsoids are those of
    the modified 3D Shepp-Logan phantom (x left-right, y anterior-posterior, z
    superior-inferior); the skull is kept at least 1.8 voxels thick so it stays closed
    at small shapes. Field of view :data:`HEAD_FOV_MM` (1.5 mm voxels by default).
    """
    shape = _check_shape(shape)
    axes = [((np.arange(n) + 0.5) / n * 2.0 - 1.0).astype(np.float32) for n in shape]
    X = axes[0][:, None, None]
    Y = axes[1][None, :, None]
    Z = axes[2][None, None, :]
    half_vox = [2.0 / n for n in shape]  # one voxel in normalised units
    vol = np.full(shape, -1000.0, dtype=np.float32)
    outer_skull = _HEAD_ELLIPSOIDS[1][1]
    for i, (add, semi, centre, phi) in enumerate(_HEAD_ELLIPSOIDS):
        semi_eff = list(semi)
        if i == 2:  # brain: keep the skull shell >= 1.8 voxels thick along every axis
            for a in range(3):
                off = abs(centre[a])
                semi_eff[a] = min(semi[a], outer_skull[a] - off - 1.8 * half_vox[a])
        c, s = math.cos(math.radians(phi)), math.sin(math.radians(phi))
        dx, dy, dz = X - centre[0], Y - centre[1], Z - centre[2]
        u = c * dx + s * dy
        v = -s * dx + c * dy
        inside = (u / semi_eff[0]) ** 2 + (v / semi_eff[1]) ** 2 + (dz / semi_eff[2]) ** 2 <= 1
        vol[np.broadcast_to(inside, shape)] += add
    data = _finish(vol, seed, blur=0.5)
    return SampleData(
        data=data,
        spacing=_spacing(HEAD_FOV_MM, shape),
        units="HU",
        description=(
            "3D Shepp-Logan-like head phantom in HU: scalp, skull shell (1000 HU) around"
            " the brain (40 HU) with ventricles (10 HU) and small lesions (65-70 HU)."
        ),
        source=f"voxwarp.sample_volumes.generators.head(shape={shape}, seed={seed})",
        license="BSD-3-Clause (voxwarp)",
    )


# --------------------------------------------------------------------------- real scans
_PACKAGE = __name__.rpartition(".")[0]  # the package holding the bundled files

_VISVIS_LICENSE = (
    "BSD-3-Clause, Copyright (c) 2012-2025, Visvis development team (see sample_volumes/README.md)"
)
_MRICRON_LICENSE = (
    "BSD-3-Clause, Copyright 2006-2010, Chris Rorden (Debian mricron-data; see"
    " sample_volumes/README.md)"
)


def _load_npz(filename: str) -> dict[str, np.ndarray]:
    raw = resources.files(_PACKAGE).joinpath(filename).read_bytes()
    with np.load(io.BytesIO(raw), allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def _triple_of(arr: np.ndarray) -> tuple[float, float, float]:
    a = np.asarray(arr, dtype=np.float64).reshape(3)
    return (float(a[0]), float(a[1]), float(a[2]))


def stent() -> SampleData:
    """CT of a stented abdominal aorta from visvis: ``uint8`` ``(128, 128, 256)``.

    The aorta with a bifurcated stent graft runs along z (superior towards +z; x
    towards the patient's left, y posterior, with the lumbar spine behind the aorta).
    Values 0..32 (quantised; no physical unit). The file has no voxel spacing:
    ``spacing`` is ``(1, 1, 1)``, a placeholder.
    """
    f = _load_npz("stent.npz")
    return SampleData(
        data=f["data"],
        spacing=_triple_of(f["spacing"]),
        units=str(f["units"]),
        description=(
            "CT of an abdominal aorta with a bifurcated stent graft (visvis sample"
            " 'stent'), quantised to 0..32; voxel spacing unknown (1, 1, 1 placeholder)."
        ),
        source="visvis 1.15.0 wheel, visvis/visvisResources/stent_vol.ssdf",
        license=_VISVIS_LICENSE,
        origin=_triple_of(f["origin"]),
    )


def colin27() -> SampleData:
    """Colin27 T1 MRI head (Debian mricron-data ``ch2.nii.gz``), 2x block-averaged.

    ``uint8`` ``(91, 109, 91)`` at 2 mm in MNI space (RAS: x to the right, y
    anterior, z superior); ``origin`` is the MNI position of voxel 0. Values are MRI
    intensities (no unit).
    """
    f = _load_npz("colin27_mri.npz")
    return SampleData(
        data=f["data"],
        spacing=_triple_of(f["spacing"]),
        units=str(f["units"]),
        description=(
            "Colin27 average T1-weighted MRI of one head in MNI space, block-averaged"
            " 2x2x2 to 2 mm voxels."
        ),
        source="Debian package mricron-data 1.2.20211006+dfsg-4,"
        " usr/share/mricron/templates/ch2.nii.gz",
        license=_MRICRON_LICENSE,
        origin=_triple_of(f["origin"]),
        axes="RAS",
    )


# --------------------------------------------------------------------------- registry
_GENERATORS: dict[str, Callable[..., SampleData]] = {
    "fish": fish,
    "tubes": tubes,
    "head": head,
    "stent": stent,
    "colin27": colin27,
}


def names() -> list[str]:
    """Names accepted by :func:`get`: the synthetic phantoms, then the real scans."""
    return list(_GENERATORS)


def get(name: str, **kwargs: object) -> SampleData:
    """The sample volume called ``name`` (see :func:`names`).

    Keyword arguments (``shape``, ``seed``) go to the generator; the real scans
    (``"stent"``, ``"colin27"``) take none. Raises ``KeyError`` for an unknown name.
    """
    try:
        fn = _GENERATORS[name]
    except KeyError:
        raise KeyError(f"unknown sample volume {name!r}; choose from {names()}") from None
    return fn(**kwargs)
