"""Numba kernels of the 3D ChainMail CPU solver (driven by
:class:`voxwarp.deform.elements.chainmail.ChainMail`).

Why numba
---------
ChainMail propagation is a sequential, queue-driven walk: an element is checked
against the neighbour that moved, moved if a link is violated, and its neighbours are
queued in turn. Which element comes next depends on the previous step, so numpy cannot
vectorise it, and a Python loop costs about a microsecond per element operation: a
local drag on a 128³ grid (2.1 M elements) must settle in well under 100 ms, and a
large drag moves 10^5..10^6 elements. The kernels are ``njit(cache=True, nogil=True)``:
compiled on first use and cached in ``__pycache__`` (the first call of a fresh
install pays a few seconds of compilation), and running without the GIL so an
interactive front end stays responsive during a drag. The relaxation sweep is
``parallel=True`` (``prange`` over x-planes of one colour of a red-black colouring).

Layout
------
Flat arrays over the ``N = nx * ny * nz`` elements in C order of ``(i, j, k)``: element
``e = (i * ny + j) * nz + k``, so the neighbour along axis ``a`` is ``e + strides[a]``
with ``strides = (ny * nz, nz, 1)``. ``x`` (N, 3) float64 positions; ``mn``, ``mx``,
``sh`` (N, 3) per element and axis limits (the model's arrays reshaped, no copy);
``links`` (N, 3) bool, element ``e`` linked to ``e + strides[a]`` (False on the last
layer along ``a``, so every forward neighbour test needs only ``links``); ``pinned``
(N,) bool, elements that may not move (fixed, held, and the ones being dragged).

Directions ``d = 0..5`` are ``+x, -x, +y, -y, +z, -z`` (axis ``d // 2``, forward when
``d`` is even).

The constraints decouple per coordinate: coordinate ``c`` of every element is bound
only by coordinate ``c`` of its linked neighbours (``lo <= x_q[c] - x_p[c] <= hi``), so
every correction below is computed coordinate by coordinate.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from voxwarp.deform.parallel import threadsafe

#: violations (mm) below this are float round-off and are not corrected
TOL = 1e-9


@njit(cache=True, nogil=True)
def _link_bounds(mn, mx, sh, p, q, a, c):  # type: ignore[no-untyped-def]
    """``(lo, hi)`` bounds of ``x_q[c] - x_p[c]`` for the link ``p -> q = p + e_a``."""
    if c == a:
        return 0.5 * (mn[p, a] + mn[q, a]), 0.5 * (mx[p, a] + mx[q, a])
    s = 0.5 * (sh[p, a] + sh[q, a])
    return -s, s


@njit(cache=True, nogil=True)
def _neighbour(links, strides, e, d):  # type: ignore[no-untyped-def]
    """The element linked to ``e`` in direction ``d``, or -1."""
    a = d >> 1
    st = strides[a]
    if d & 1 == 0:
        if links[e, a]:
            return e + st
        return -1
    if e >= st and links[e - st, a]:
        return e - st
    return -1


@njit(cache=True, nogil=True)
def _follow_bounds(x, mn, mx, sh, e, n, d, c):  # type: ignore[no-untyped-def]
    """Interval of ``x_n[c]`` allowed by the link to ``e`` (``n`` is ``e``'s neighbour in
    direction ``d``)."""
    a = d >> 1
    if d & 1 == 0:  # n = e + e_a: link (e, n), x_n - x_e in [lo, hi]
        lo, hi = _link_bounds(mn, mx, sh, e, n, a, c)
        return x[e, c] + lo, x[e, c] + hi
    lo, hi = _link_bounds(mn, mx, sh, n, e, a, c)  # link (n, e): x_e - x_n in [lo, hi]
    return x[e, c] - hi, x[e, c] - lo


@njit(cache=True, nogil=True)
def _interval(x, mn, mx, sh, links, strides, e, c):  # type: ignore[no-untyped-def]
    """Interval ``(L, U)`` of ``x_e[c]`` allowed by all of ``e``'s links (``L > U``: the
    neighbours conflict)."""
    lo_all = -np.inf
    hi_all = np.inf
    for d in range(6):
        n = _neighbour(links, strides, e, d)
        if n < 0:
            continue
        # e is n's neighbour in the opposite direction d ^ 1
        lo, hi = _follow_bounds(x, mn, mx, sh, n, e, d ^ 1, c)
        lo_all = max(lo_all, lo)
        hi_all = min(hi_all, hi)
    return lo_all, hi_all


@njit(cache=True, nogil=True)
def _grow_queue(q):  # type: ignore[no-untyped-def]
    out = np.empty((q.shape[0], 2 * q.shape[1]), np.int64)
    out[:, : q.shape[1]] = q
    return out


@njit(cache=True, nogil=True)
def _heap_push(keys, vals, size, key, val):  # type: ignore[no-untyped-def]
    """Push onto a max-heap held in ``keys``/``vals`` (grown when full)."""
    if size == keys.shape[0]:
        k2 = np.empty(2 * size, np.float64)
        v2 = np.empty(2 * size, np.int64)
        k2[:size] = keys
        v2[:size] = vals
        keys, vals = k2, v2
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if keys[p] >= key:
            break
        keys[i] = keys[p]
        vals[i] = vals[p]
        i = p
    keys[i] = key
    vals[i] = val
    return keys, vals, size + 1


@njit(cache=True, nogil=True)
def _heap_pop(keys, vals, size):  # type: ignore[no-untyped-def]
    """Pop the largest key of a max-heap: ``(key, val, new size)``."""
    key = keys[0]
    val = vals[0]
    size -= 1
    if size > 0:
        lk = keys[size]
        lv = vals[size]
        i = 0
        while True:
            left = 2 * i + 1
            if left >= size:
                break
            m = left
            if left + 1 < size and keys[left + 1] > keys[left]:
                m = left + 1
            if keys[m] <= lk:
                break
            keys[i] = keys[m]
            vals[i] = vals[m]
            i = m
        keys[i] = lk
        vals[i] = lv
    return key, val, size


@njit(cache=True, nogil=True)
def propagate(  # type: ignore[no-untyped-def]
    x,
    mn,
    mx,
    sh,
    links,
    pinned,
    mark,
    slot,
    epoch,
    strides,
    seeds,
    targets,
    gibson,
    repair,
    commit,
    max_pops,
    t_idx,
    t_old,
):
    """Move the ``seeds`` to ``targets`` and propagate until every link is satisfied.

    Parameters
    ----------
    x, mn, mx, sh, links, pinned, strides
        See the module doc; ``x`` is changed in place.
    mark, slot, epoch
        ``mark[e] == epoch`` when ``e`` was moved in this call, its old position then
        being ``t_old[slot[e]]`` (``epoch`` is new for every call, so nothing is cleared).
    seeds, targets
        (m,) element indices and (m, 3) their new positions (the seeds must be pinned).
    gibson
        Propagate with Gibson's six sponsor lists first, then clean up what they leave
        violated with the priority queue; else the priority queue alone ("enhanced").
    repair
        Also queue every violated link of the whole grid (for a state that did not
        satisfy the constraints to begin with).
    commit
        Keep the result; False undoes a successful propagation too (a trial).
    max_pops
        Give up (as infeasible) after this many priority-queue pops.
    t_idx, t_old
        (N,) and (N, 3) scratch: the moved elements and their old positions.

    Returns
    -------
    tuple
        ``(ok, moved, checks, fixes, capped, n_t)``: False when a pinned element would
        have to move (``x`` is then restored), the number of elements whose position
        changed, constraint checks made (list entries and queue pops), element-coordinate
        corrections made by the priority queue (Gibson's cleanup), whether ``max_pops``
        was hit, and the length of the record ``t_idx`` / ``t_old``.
    """
    n_t = 0
    checks = 0
    fixes = 0
    capped = False
    ok = True
    nv = np.empty(3, np.float64)

    for m in range(seeds.shape[0]):
        e = seeds[m]
        if mark[e] != epoch:
            mark[e] = epoch
            slot[e] = n_t
            t_idx[n_t] = e
            for c in range(3):
                t_old[n_t, c] = x[e, c]
            n_t += 1
        for c in range(3):
            x[e, c] = targets[m, c]

    # ------------------------------------------------------------ Gibson 1997
    if gibson and seeds.shape[0] > 0:
        q = np.empty((6, 64), np.int64)
        head = np.zeros(6, np.int64)
        tail = np.zeros(6, np.int64)
        for m in range(seeds.shape[0]):
            e = seeds[m]
            for d in range(6):
                n = _neighbour(links, strides, e, d)
                if n >= 0 and mark[n] != epoch:
                    if tail[d] == q.shape[1]:
                        q = _grow_queue(q)
                    q[d, tail[d]] = n
                    tail[d] += 1
        busy = True
        while busy and ok:
            for d in range(6):
                a = d >> 1
                while head[d] < tail[d]:
                    e = q[d, head[d]]
                    head[d] += 1
                    checks += 1
                    if mark[e] == epoch:  # moved already: processed at most once
                        continue
                    s = e - strides[a] if d & 1 == 0 else e + strides[a]  # the sponsor
                    moved = False
                    for c in range(3):
                        lo, hi = _follow_bounds(x, mn, mx, sh, s, e, d, c)
                        v = x[e, c]
                        if v < lo - TOL:
                            v = lo
                            moved = True
                        elif v > hi + TOL:
                            v = hi
                            moved = True
                        nv[c] = v
                    if not moved:  # inside the slack: the wave stops here
                        continue
                    if pinned[e]:
                        ok = False
                        break
                    mark[e] = epoch
                    slot[e] = n_t
                    t_idx[n_t] = e
                    for c in range(3):
                        t_old[n_t, c] = x[e, c]
                        x[e, c] = nv[c]
                    n_t += 1
                    # x lists feed x (same way), y and z; y lists feed y and z; z lists z
                    for d2 in range(6):
                        a2 = d2 >> 1
                        if (a2 == a and d2 != d) or a2 < a:
                            continue
                        n = _neighbour(links, strides, e, d2)
                        if n >= 0 and mark[n] != epoch:
                            if tail[d2] == q.shape[1]:
                                q = _grow_queue(q)
                            q[d2, tail[d2]] = n
                            tail[d2] += 1
                if not ok:
                    break
                head[d] = 0
                tail[d] = 0
            busy = False
            for d in range(6):
                if tail[d] > head[d]:
                    busy = True

    # ------------------------------------------------------------ priority queue
    if ok:
        keys = np.empty(256, np.float64)
        vals = np.empty(256, np.int64)
        size = 0
        # seeds of the queue: the links of everything moved so far (enhanced: the
        # dragged elements; gibson: whatever the sponsor lists left violated) or, to
        # repair a state, every link
        if repair:
            n_src = x.shape[0]
        else:
            n_src = n_t
        for i in range(n_src):
            e = i if repair else t_idx[i]
            for d in range(6):
                if repair and d & 1 == 1:
                    continue  # every link once, from its lower end
                n = _neighbour(links, strides, e, d)
                if n < 0:
                    continue
                for c in range(3):
                    lo, hi = _follow_bounds(x, mn, mx, sh, e, n, d, c)
                    v = x[n, c]
                    if lo - TOL <= v <= hi + TOL:
                        continue
                    # the end that moved less (in this coordinate) follows the other
                    de = abs(x[e, c] - (t_old[slot[e], c] if mark[e] == epoch else x[e, c]))
                    dn = abs(v - (t_old[slot[n], c] if mark[n] == epoch else v))
                    push_n = de >= dn
                    if de == dn and pinned[n]:
                        push_n = False  # no motion to follow (a repair): move a free end
                    if push_n:
                        target = lo if v < lo else hi
                        f = n
                    else:
                        lo_e, hi_e = _follow_bounds(x, mn, mx, sh, n, e, d ^ 1, c)
                        target = lo_e if x[e, c] < lo_e else hi_e
                        f = e
                    start = t_old[slot[f], c] if mark[f] == epoch else x[f, c]
                    up = 1 if target > x[f, c] else 0
                    keys, vals, size = _heap_push(
                        keys, vals, size, abs(target - start), (f * 3 + c) * 2 + up
                    )
        pops = 0
        while size > 0:
            _key, val, size = _heap_pop(keys, vals, size)
            pops += 1
            if pops > max_pops:
                ok = False
                capped = True
                break
            up = val & 1
            c = (val >> 1) % 3
            e = (val >> 1) // 3
            checks += 1
            lo_all, hi_all = _interval(x, mn, mx, sh, links, strides, e, c)
            v = x[e, c]
            if lo_all <= hi_all:
                nvc = min(max(v, lo_all), hi_all)
            elif up == 1:  # the neighbours conflict: follow the push (the other side
                nvc = max(v, lo_all)  # was queued when this element moved)
            else:
                nvc = min(v, hi_all)
            if abs(nvc - v) <= TOL:
                continue  # stale: satisfied meanwhile
            if pinned[e]:
                ok = False
                break
            if mark[e] != epoch:
                mark[e] = epoch
                slot[e] = n_t
                t_idx[n_t] = e
                for cc in range(3):
                    t_old[n_t, cc] = x[e, cc]
                n_t += 1
            x[e, c] = nvc
            fixes += 1
            for d in range(6):
                n = _neighbour(links, strides, e, d)
                if n < 0:
                    continue
                lo, hi = _follow_bounds(x, mn, mx, sh, e, n, d, c)
                vn = x[n, c]
                if vn < lo - TOL:
                    target = lo
                elif vn > hi + TOL:
                    target = hi
                else:
                    continue
                start = t_old[slot[n], c] if mark[n] == epoch else vn
                keys, vals, size = _heap_push(
                    keys,
                    vals,
                    size,
                    abs(target - start),
                    (n * 3 + c) * 2 + (1 if target > vn else 0),
                )

    moved = 0
    if ok and commit:
        for i in range(n_t):
            e = t_idx[i]
            if x[e, 0] != t_old[i, 0] or x[e, 1] != t_old[i, 1] or x[e, 2] != t_old[i, 2]:
                moved += 1
    else:
        for i in range(n_t):
            e = t_idx[i]
            if x[e, 0] != t_old[i, 0] or x[e, 1] != t_old[i, 1] or x[e, 2] != t_old[i, 2]:
                moved += 1
            for c in range(3):
                x[e, c] = t_old[i, c]
    return ok, moved, checks, fixes, capped, n_t


@threadsafe
@njit(cache=True, nogil=True, parallel=True)
def relax_sweep(x, rest, mn, mx, sh, links, frozen, shape, box, colour):  # type: ignore[no-untyped-def]
    """One colour of a red-black Gauss-Seidel sweep of constrained Laplacian smoothing.

    Every free element ``e`` with ``(i + j + k) % 2 == colour`` inside ``box``
    (``[i0, i1, j0, j1, k0, k1]``, half-open) moves, per coordinate, to
    ``rest_e + mean(u_n)`` (``u = x - rest`` of its linked neighbours ``n``), clamped to
    the interval its links allow with the neighbours where they are. That is the exact
    minimiser of the smoothness energy ``sum_links |u_q - u_p|^2`` over ``x_e`` within
    the constraints, so the energy never grows and the constraints stay satisfied.
    Elements of one colour have no links among each other: they are updated in
    parallel.
    """
    ny = shape[1]
    nz = shape[2]
    strides = np.array([ny * nz, nz, 1], np.int64)
    for i in prange(box[0], box[1]):
        lo = np.empty(3, np.float64)
        hi = np.empty(3, np.float64)
        su = np.empty(3, np.float64)
        for j in range(box[2], box[3]):
            k_first = box[4] + ((i + j + box[4] + colour) & 1)
            for k in range(k_first, box[5], 2):
                e = (i * ny + j) * nz + k
                if frozen[e]:
                    continue
                cnt = 0
                for c in range(3):
                    lo[c] = -np.inf
                    hi[c] = np.inf
                    su[c] = 0.0
                for d in range(6):
                    n = _neighbour(links, strides, e, d)
                    if n < 0:
                        continue
                    cnt += 1
                    a = d >> 1
                    p, q = (e, n) if d & 1 == 0 else (n, e)
                    s = 0.5 * (sh[p, a] + sh[q, a])
                    for c in range(3):
                        su[c] += x[n, c] - rest[n, c]
                        if c == a:
                            dlo = 0.5 * (mn[p, a] + mn[q, a])
                            dhi = 0.5 * (mx[p, a] + mx[q, a])
                        else:
                            dlo = -s
                            dhi = s
                        # x_q - x_p in [dlo, dhi]
                        if d & 1 == 0:  # e = p: x_e in [x_n - dhi, x_n - dlo]
                            lo[c] = max(lo[c], x[n, c] - dhi)
                            hi[c] = min(hi[c], x[n, c] - dlo)
                        else:  # e = q: x_e in [x_n + dlo, x_n + dhi]
                            lo[c] = max(lo[c], x[n, c] + dlo)
                            hi[c] = min(hi[c], x[n, c] + dhi)
                if cnt == 0:
                    continue
                for c in range(3):
                    if lo[c] <= hi[c]:
                        target = rest[e, c] + su[c] / cnt
                        x[e, c] = min(max(target, lo[c]), hi[c])
