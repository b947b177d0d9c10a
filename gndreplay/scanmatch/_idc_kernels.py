"""Numba kernels of the IDC matcher: render the local map as a reference scan, then iterate IDC.

Frames: the *reference frame* is the laser pose at which the map is rendered (the prediction). The estimate
(x, y, th) is the pose of the new scan's laser in that frame. The reference scan has ``n_bins`` bearing bins
over the full circle, bin b covering [-pi + b res, -pi + (b + 1) res); bin indices wrap around.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .. import detmath as dm

TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always", error_model="numpy")
def _bin(a: float, inv_res: float, n_bins: int) -> int:
    b = int((a + math.pi) * inv_res)
    if b < 0:
        return 0
    if b >= n_bins:
        return n_bins - 1
    return b


@njit(cache=True, inline="always", error_model="numpy")
def fast_atan2(y: float, x: float) -> float:
    """atan2 within 2e-6 rad, ~5x faster than math.atan2 (minimax polynomial of atan on [0, 1]).

    Used for binning and for bearings inside the iterations: 2e-6 rad is 0.1 mm at 40 m.
    """
    ax = abs(x)
    ay = abs(y)
    mx = max(ax, ay)
    if mx == 0.0:
        return 0.0
    z = min(ax, ay) / mx
    z2 = z * z
    p = 0.05265332 - z2 * 0.01172120
    a = z * (0.99997726 + z2 * (-0.33262347 + z2 * (0.19354346 + z2 * (-0.11643287 + z2 * p))))
    if ay > ax:
        a = 0.5 * math.pi - a
    if x < 0.0:
        a = math.pi - a
    if y < 0.0:
        a = -a
    return a


@njit(cache=True, inline="always", error_model="numpy")
def _pm_pi(a: float) -> float:
    """Bring a difference of two angles in (-pi, pi] (so within (-2 pi, 2 pi)) back to [-pi, pi]."""
    if a > math.pi:
        return a - TWO_PI
    if a < -math.pi:
        return a + TWO_PI
    return a


@njit(cache=True, error_model="numpy")
def scan_points(ranges, angles, min_r, max_r):
    """The beams with a range in [min_r, max_r] (no-return +inf and invalid nan fail the test) as points of
    the laser frame: (x, y, range, parity of the beam's index), each of length <= len(ranges)."""
    n = ranges.shape[0]
    px = np.empty(n)
    py = np.empty(n)
    pr = np.empty(n)
    par = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        r = ranges[i]
        if r >= min_r and r <= max_r:
            px[m] = r * dm.cos(angles[i])
            py[m] = r * dm.sin(angles[i])
            pr[m] = r
            par[m] = i & 1
            m += 1
    return px[:m], py[:m], pr[:m], par[:m]


@njit(cache=True, error_model="numpy")
def deskew_points(px, py, pr, par, delay, vx, vy, w):
    """Motion compensation of an interlaced scan: the odd beams are taken ``delay`` seconds after the even
    ones, so with the laser moving at (vx, vy, w) (laser frame, m/s and rad/s) each point is moved to where
    it lies at the mean beam time: p' = R(w tau) p + v tau, tau = (parity - mean parity) * delay.

    Returns the compensated (x, y, range); copies of the inputs when delay or the motion is 0.
    """
    n = px.shape[0]
    qx = px.copy()
    qy = py.copy()
    qr = pr.copy()
    if n == 0 or delay == 0.0 or (vx == 0.0 and vy == 0.0 and w == 0.0):
        return qx, qy, qr
    mean = 0.0
    for i in range(n):
        mean += par[i]
    mean /= n
    for i in range(n):
        tau = (par[i] - mean) * delay
        c, s = dm.cos(w * tau), dm.sin(w * tau)
        qx[i] = c * px[i] - s * py[i] + vx * tau
        qy[i] = s * px[i] + c * py[i] + vy * tau
        qr[i] = math.sqrt(qx[i] * qx[i] + qy[i] * qy[i])
    return qx, qy, qr


@njit(cache=True, error_model="numpy")
def render_reference(kf_xy, kf_n, ox, oy, oth, n_bins, min_r, max_r, blend_m, seg_abs_m, seg_rel, gap_bins):
    """Render keyframe points (world frame) as a polar reference scan seen from the pose (ox, oy, oth).

    Per bearing bin the nearest return wins (occlusion), and the points within ``blend_m`` behind it are
    averaged with it: several keyframes see the same wall, and the average is less noisy than any one scan.
    ``nxt[b]`` is the next valid bin after b (at most ``gap_bins`` on) when both lie on one surface (closer
    than seg_abs_m + seg_rel * range * bins apart), else -1: the polyline that the IDC rules interpolate
    along never bridges a depth discontinuity.

    Returns (ref_x, ref_y, ref_r, ref_a, ok, nxt), each of length n_bins, in the reference frame (range and
    bearing of each bin's point about the reference origin).
    """
    inv_res = n_bins / TWO_PI
    c, s = dm.cos(oth), dm.sin(oth)
    rmin = np.full(n_bins, np.inf)
    total = 0
    for k in range(kf_n.shape[0]):
        total += kf_n[k]
    lx = np.empty(total)
    ly = np.empty(total)
    lr = np.empty(total)
    lb = np.empty(total, dtype=np.int64)
    m = 0
    max_r2 = max_r * max_r
    min_r2 = min_r * min_r
    for k in range(kf_n.shape[0]):
        for i in range(kf_n[k]):
            dx = kf_xy[k, i, 0] - ox
            dy = kf_xy[k, i, 1] - oy
            x = c * dx + s * dy
            y = -s * dx + c * dy
            r2 = x * x + y * y
            if r2 < min_r2 or r2 > max_r2:
                continue
            r = math.sqrt(r2)
            b = _bin(fast_atan2(y, x), inv_res, n_bins)
            lx[m] = x
            ly[m] = y
            lr[m] = r
            lb[m] = b
            rmin[b] = min(r, rmin[b])  # no branch: which keyframe's point is nearer is unpredictable
            m += 1
    sx = np.zeros(n_bins)
    sy = np.zeros(n_bins)
    cnt = np.zeros(n_bins)
    for i in range(m):
        b = lb[i]
        w = 1.0 if lr[i] <= rmin[b] + blend_m else 0.0  # a select, not an unpredictable branch
        sx[b] += w * lx[i]
        sy[b] += w * ly[i]
        cnt[b] += w
    ref_x = np.zeros(n_bins)
    ref_y = np.zeros(n_bins)
    ref_r = np.zeros(n_bins)
    ref_a = np.zeros(n_bins)
    ok = cnt > 0.0
    for b in range(n_bins):
        if ok[b]:
            ref_x[b] = sx[b] / cnt[b]
            ref_y[b] = sy[b] / cnt[b]
            ref_r[b] = math.sqrt(ref_x[b] ** 2 + ref_y[b] ** 2)
            ref_a[b] = dm.atan2(ref_y[b], ref_x[b])
    nxt = np.full(n_bins, -1, dtype=np.int64)
    for b in range(n_bins):
        if not ok[b]:
            continue
        for g in range(1, gap_bins + 1):
            j = b + g
            if j >= n_bins:
                j -= n_bins
            if ok[j]:
                lim = seg_abs_m + seg_rel * max(ref_r[b], ref_r[j]) * g
                if (ref_x[j] - ref_x[b]) ** 2 + (ref_y[j] - ref_y[b]) ** 2 <= lim * lim:
                    nxt[b] = j
                break
    return ref_x, ref_y, ref_r, ref_a, ok, nxt


# how far beyond a polyline's open end its surface's continuation is looked for in the keyframes' views
BEYOND_RAD = math.radians(2.0)


@njit(cache=True, error_model="numpy")
def view_row(x, y, th, first, last, max_r):
    """A keyframe's view as unseen_ends reads it: laser x, y (corrected frame), the unit vectors of its first
    and last bearing, and its range limit, negative when the view spans more than pi."""
    a = th + first
    b = th + last
    return np.array([x, y, dm.cos(a), dm.sin(a), dm.cos(b), dm.sin(b), max_r if last - first <= math.pi
                     else -max_r])


@njit(cache=True, error_model="numpy")
def unseen_ends(ref_x, ref_y, nxt, kf_view, kf_n, ox, oy, oth):
    """Per bin, which open ends of the reference polyline no keyframe could have seen past: bit 1 a
    polyline's first point, bit 2 its last, set when the surface's continuation ``BEYOND_RAD`` further on
    (same range, seen from the reference's origin (ox, oy, oth)) lay outside the view of every keyframe.

    ``kf_view`` holds each keyframe's view (rows of view_row; rows with ``kf_n`` 0 are empty): a point is in
    it when within the range limit and between the first and the last bearing (two cross products). Such an
    end is where the keyframes' field of view ended, not where the surface ends: the map does not know what
    lies beyond (see _off_end)."""
    n_bins = ref_x.shape[0]
    has_prev = np.zeros(n_bins, dtype=np.bool_)
    for j in range(n_bins):
        if nxt[j] >= 0:
            has_prev[nxt[j]] = True
    out = np.zeros(n_bins, dtype=np.uint8)
    co = dm.cos(oth)
    so = dm.sin(oth)
    for e in range(n_bins):
        first = nxt[e] >= 0 and not has_prev[e]
        last = nxt[e] < 0 and has_prev[e]
        if not (first or last):
            continue
        r = math.sqrt(ref_x[e] * ref_x[e] + ref_y[e] * ref_y[e])
        a = fast_atan2(ref_y[e], ref_x[e]) + (BEYOND_RAD if last else -BEYOND_RAD)
        lx = r * dm.cos(a)
        ly = r * dm.sin(a)
        bx = ox + co * lx - so * ly  # the continuation in the corrected frame
        by = oy + so * lx + co * ly
        seen = False
        for k in range(kf_view.shape[0]):
            if kf_n[k] == 0:
                continue
            dx = bx - kf_view[k, 0]
            dy = by - kf_view[k, 1]
            rmax = kf_view[k, 6]
            if dx * dx + dy * dy >= rmax * rmax:
                continue
            after_first = kf_view[k, 2] * dy - kf_view[k, 3] * dx >= 0.0
            before_last = dx * kf_view[k, 5] - dy * kf_view[k, 4] >= 0.0
            if (after_first and before_last) if rmax > 0.0 else (after_first or before_last):
                seen = True
                break
        if not seen:
            out[e] = 2 if last else 1
    return out


@njit(cache=True, inline="always", error_model="numpy")
def _off_end(j, u, nxt, unseen):
    """Whether the closest point u on segment j is an open end of its polyline that no keyframe saw past
    (``unseen``, see unseen_ends): the segment's end (u = 1) or its start (u = 0). A scan point paired
    there lies past the mapped extent of that surface, where the keyframes' field of view ended: a
    closest-point pair with the end pulls the scan along the surface towards the mapped part, and the pull
    builds up while the view sweeps along a wall (turning on the spot beside one). IDC's closest-point rule
    leaves such pairs out (Rusinkiewicz & Levoy 2001, rejecting pairs on the reference's boundary); the
    point-to-line polish keeps them, the surface's line being what the point lies on. An end that a
    keyframe saw past (a door jamb, a corner, the edge of a table) is kept: it observes the motion along
    the wall."""
    if u >= 1.0:
        return (unseen[np.uint64(nxt[np.uint64(j)])] & 2) != 0
    if u <= 0.0:
        return (unseen[np.uint64(j)] & 1) != 0
    return False


@njit(cache=True, inline="always", error_model="numpy")
def _closest_on_polyline(qx, qy, rq2, bq, w_max, ref_x, ref_y, nxt, cover, seg_ex, seg_ey, seg_il, best_d2,
                         sin2):
    """Closest point to q = (qx, qy) on the reference polyline, searching outwards from q's bin bq.

    ``cover[b]`` is the segment (its first bin) whose bearing span contains bin b, or the isolated point in
    b, else -1. A segment not met within k bins of bq lies at least (k - 2) bins of bearing away, so at
    least |q| sin((k - 2) res) from q: the search stops once ``rq2 * sin2[k]`` exceeds the best squared
    distance so far (``best_d2`` starts as the squared gate). Returns (j, u, d2): the segment (or point) j
    of the closest point, -1 if none within the gate, its parameter u along the segment, the squared
    distance. The closest point is ref[j] + u seg[j].
    """
    n_bins = ref_x.shape[0]
    jbest = -1
    ubest = 0.0
    # a segment covers consecutive bins: skip a j just tried on the same side (or at k = 0), its distance
    # is the same and cannot beat best_d2 (strict <): the result is that of trying every bin. Points without
    # a segment have seg_ex = seg_ey = seg_il = 0 (u = 0), and so do zero-length segments.
    last_r = -2
    last_l = -2
    for k in range(0, w_max + 1):
        if rq2 * sin2[np.uint64(k)] > best_d2:
            break
        b = bq + k
        if b >= n_bins:
            b -= n_bins
        j = cover[b]
        if j >= 0 and j != last_r:
            last_r = j
            if k == 0:
                last_l = j
            dx = qx - ref_x[j]
            dy = qy - ref_y[j]
            u = min(1.0, max(0.0, (dx * seg_ex[j] + dy * seg_ey[j]) * seg_il[j]))
            dx -= u * seg_ex[j]
            dy -= u * seg_ey[j]
            d2 = dx * dx + dy * dy
            if d2 < best_d2:
                best_d2 = d2
                jbest = j
                ubest = u
        if k == 0:
            continue
        b = bq - k
        if b < 0:
            b += n_bins
        j = cover[b]
        if j >= 0 and j != last_l:
            last_l = j
            dx = qx - ref_x[j]
            dy = qy - ref_y[j]
            u = min(1.0, max(0.0, (dx * seg_ex[j] + dy * seg_ey[j]) * seg_il[j]))
            dx -= u * seg_ex[j]
            dy -= u * seg_ey[j]
            d2 = dx * dx + dy * dy
            if d2 < best_d2:
                best_d2 = d2
                jbest = j
                ubest = u
    return jbest, ubest, best_d2


@njit(cache=True, inline="always", error_model="numpy")
def _matching_range(rq, aq, bq, bw, ref_r, ref_a, ok, nxt):
    """Matching-range-point rule: the bearing offset d, |d| <= bw and smallest, at which the reference
    polyline (range interpolated linearly in bearing) has the range rq of the point at bearing aq.

    Searches outwards from bin bq, both sides in turn; a side stops once its segments start beyond the best
    offset found. Returns (found, d).
    """
    n_bins = ref_r.shape[0]
    w_max = min(n_bins // 2 - 1, int(bw * n_bins / TWO_PI) + 2)
    best = bw
    dbest = 0.0
    found = False
    open_r = True
    open_l = True
    for k in range(0, w_max + 1):
        if not (open_r or open_l):
            break
        for side in range(2):
            if (side == 0 and not open_r) or (side == 1 and not open_l):
                continue
            j = bq + k if side == 0 else bq - k - 1
            if j >= n_bins:
                j -= n_bins
            elif j < 0:
                j += n_bins
            if not ok[j]:
                continue
            m = nxt[j]
            if m < 0:
                continue
            d1 = _pm_pi(ref_a[j] - aq)
            d2 = _pm_pi(ref_a[np.uint64(m)] - aq)
            if side == 0 and min(d1, d2) > best:
                open_r = False
                continue
            if side == 1 and max(d1, d2) < -best:
                open_l = False
                continue
            r1 = ref_r[j] - rq
            r2 = ref_r[np.uint64(m)] - rq
            if r1 * r2 > 0.0 or abs(d2 - d1) > math.pi:
                continue
            u = 0.5 if r1 == r2 else r1 / (r1 - r2)
            d = d1 + u * (d2 - d1)
            if abs(d) < best:
                best = abs(d)
                dbest = d
                found = True
    return found, dbest


@njit(cache=True, error_model="numpy")
def _weighted_median(v, w):
    """Weighted median of v: a robust location of the matching-range-point offsets."""
    order = np.argsort(v)
    half = 0.5 * np.sum(w)
    acc = 0.0
    for k in range(order.shape[0]):
        acc += w[order[k]]
        if acc >= half:
            return v[order[k]]
    return v[order[-1]]


@njit(cache=True, error_model="numpy")
def _sin2_table(n_bins, w_max):
    """sin² of the smallest bearing difference, (k - 2) bins clamped to [0, pi/2], of a segment first met k
    bins away from the query's bin (see _closest_on_polyline)."""
    res = TWO_PI / n_bins
    out = np.empty(w_max + 1)
    for k in range(w_max + 1):
        out[k] = dm.sin(min(max(0.0, (k - 2) * res), 0.5 * math.pi)) ** 2
    return out


@njit(cache=True, error_model="numpy")
def segments(ref_x, ref_y, ok, nxt, normal_chord_m):
    """Per bin: the vector to the next point of the polyline, its inverse squared length, the unit normal of
    the surface there, and ``cover`` (see _closest_on_polyline).

    The normal is taken across a chord of at least ``normal_chord_m`` along the polyline (extending up to 4
    points each way), not across the single segment: two points 1 cm apart with 5 mm of noise tilt a
    segment by up to 30 deg, which would invent constraints (a bare corridor would look observable along
    its axis) and bias the point-to-line fit.
    """
    n_bins = ref_x.shape[0]
    prv = np.full(n_bins, -1, dtype=np.int64)
    cover = np.full(n_bins, -1, dtype=np.int64)
    for j in range(n_bins):
        m = nxt[j]
        if m >= 0:
            prv[m] = j
            span = m - j
            if span < 0:
                span += n_bins
            for g in range(span):
                jg = j + g
                if jg >= n_bins:
                    jg -= n_bins
                cover[jg] = j
    for j in range(n_bins):
        if cover[j] < 0 and ok[j]:
            cover[j] = j
    ex = np.zeros(n_bins)
    ey = np.zeros(n_bins)
    il = np.zeros(n_bins)
    nx = np.zeros(n_bins)
    ny = np.zeros(n_bins)
    lim2 = normal_chord_m * normal_chord_m
    for j in range(n_bins):
        m = nxt[j]
        if m < 0:
            continue
        ex[j] = ref_x[m] - ref_x[j]
        ey[j] = ref_y[m] - ref_y[j]
        ll = ex[j] ** 2 + ey[j] ** 2
        if ll <= 0.0:
            continue
        il[j] = 1.0 / ll
        a = j
        b = m
        for _ in range(4):
            tx = ref_x[b] - ref_x[a]
            ty = ref_y[b] - ref_y[a]
            if tx * tx + ty * ty >= lim2:
                break
            moved = False
            if prv[a] >= 0:
                a = prv[a]
                moved = True
            if nxt[b] >= 0:
                b = nxt[b]
                moved = True
            if not moved:
                break
        tx = ref_x[b] - ref_x[a]
        ty = ref_y[b] - ref_y[a]
        inv = 1.0 / math.sqrt(tx * tx + ty * ty)
        nx[j] = -ty * inv
        ny[j] = tx * inv
    return ex, ey, il, nx, ny, cover


@njit(cache=True, error_model="numpy")
def idc_align(px, py, pr, ref_x, ref_y, ref_r, ref_a, ok, nxt, cover, seg_ex, seg_ey, seg_il, unseen, x0, y0,
              th0, max_iter, win0, win_tau, win_min, gate0, gate_min, tol_t, tol_r, max_cp_bins, stride,
              mrp_every):
    """Iterative Dual Correspondence (Lu & Milios 1997) of the points (px, py) against the reference.

    Each iteration pairs the points twice. Closest-point rule: each transformed point q with the closest
    point of the reference polyline, gated by a distance that shrinks from gate0 to gate_min, except at an
    open end of the polyline that no keyframe saw past (``unseen``, see _off_end); the least-squares rigid
    fit of these pairs gives the translation. Matching-range-point rule: q with the point of the polyline
    of equal range |q| within the bearing window [-Bw, +Bw] of q,
    Bw(k) = max(win_min, win0 exp(-k / tau)); the offsets give the rotation (about the reference origin,
    which is within centimetres of the scan's origin). The rotation update is the range²-weighted median of
    the offsets (the weighted mean is the least-squares answer; the median ignores the wrong pairs of corners
    and clutter). The closest-point rule uses every ``stride``-th point, the matching-range rule every
    ``mrp_every``-th of those (the rotation needs fewer points; its wide early windows are the costly part).

    Returns (x, y, th, iterations, converged).
    """
    n = px.shape[0]
    n_bins = ref_x.shape[0]
    inv_res = n_bins / TWO_PI
    sin2 = _sin2_table(n_bins, max_cp_bins)
    md = np.empty(n)
    mw = np.empty(n)
    x = x0
    y = y0
    th = th0
    it = 0
    converged = False
    while it < max_iter:
        bw = max(win_min, win0 * dm.exp(-it / win_tau))
        gate = max(gate_min, gate0 * dm.exp(-it / win_tau))
        gate2 = gate * gate
        w_mrp = min(n_bins // 2 - 1, int(bw * n_bins / TWO_PI) + 2)
        c, s = dm.cos(th), dm.sin(th)
        n_m = 0
        n_cp = 0
        spx = 0.0
        spy = 0.0
        scx = 0.0
        scy = 0.0
        sxx = 0.0
        sxy = 0.0
        syx = 0.0
        syy = 0.0
        mrp_count = 0  # i_s % mrp_every without the integer division: every mrp_every-th point does MRP
        for i in range(0, n, stride):
            qx = c * px[i] - s * py[i] + x
            qy = s * px[i] + c * py[i] + y
            rq2 = qx * qx + qy * qy
            aq = fast_atan2(qy, qx)
            bq = _bin(aq, inv_res, n_bins)
            # closest point (see _closest_on_polyline; inlined by hand: a call passing arrays costs an
            # atomic incref/decref per array, more than the search itself)
            best_d2 = gate2
            j = -1
            u = 0.0
            last_r = -2
            last_l = -2
            for k in range(0, max_cp_bins + 1):
                if rq2 * sin2[np.uint64(k)] > best_d2:
                    break
                b = bq + k
                if b >= n_bins:
                    b -= n_bins
                jj = cover[np.uint64(b)]
                uj = np.uint64(jj)  # unsigned index: no negative-index wraparound code
                if jj >= 0 and jj != last_r:
                    last_r = jj
                    if k == 0:
                        last_l = jj
                    dx = qx - ref_x[uj]
                    dy = qy - ref_y[uj]
                    uu = min(1.0, max(0.0, (dx * seg_ex[uj] + dy * seg_ey[uj]) * seg_il[uj]))
                    dx -= uu * seg_ex[uj]
                    dy -= uu * seg_ey[uj]
                    dd = dx * dx + dy * dy
                    if dd < best_d2:
                        best_d2 = dd
                        j = jj
                        u = uu
                if k == 0:
                    continue
                b = bq - k
                if b < 0:
                    b += n_bins
                jj = cover[np.uint64(b)]
                uj = np.uint64(jj)  # unsigned index: no negative-index wraparound code
                if jj >= 0 and jj != last_l:
                    last_l = jj
                    dx = qx - ref_x[uj]
                    dy = qy - ref_y[uj]
                    uu = min(1.0, max(0.0, (dx * seg_ex[uj] + dy * seg_ey[uj]) * seg_il[uj]))
                    dx -= uu * seg_ex[uj]
                    dy -= uu * seg_ey[uj]
                    dd = dx * dx + dy * dy
                    if dd < best_d2:
                        best_d2 = dd
                        j = jj
                        u = uu
            if j >= 0 and seg_il[j] > 0.0 and _off_end(j, u, nxt, unseen):
                j = -1
            if j >= 0:
                cx = ref_x[j] + u * seg_ex[j]
                cy = ref_y[j] + u * seg_ey[j]
                n_cp += 1
                spx += px[i]
                spy += py[i]
                scx += cx
                scy += cy
                sxx += px[i] * cx
                sxy += px[i] * cy
                syx += py[i] * cx
                syy += py[i] * cy
            mrp_count -= 1
            if mrp_count > 0:
                continue
            mrp_count = mrp_every
            # matching range point (see _matching_range; inlined by hand like the closest point)
            rq = math.sqrt(rq2)
            best = bw
            d = 0.0
            fm = False
            open_r = True
            open_l = True
            # (the two sides written out; nxt is -1 where ok is False, so ok needs no test)
            for k in range(0, w_mrp + 1):
                if not (open_r or open_l):
                    break
                if open_r:
                    jj = bq + k
                    if jj >= n_bins:
                        jj -= n_bins
                    uj = np.uint64(jj)  # unsigned index: no negative-index wraparound code
                    m = nxt[uj]
                    if m >= 0:
                        d1 = _pm_pi(ref_a[uj] - aq)
                        d2 = _pm_pi(ref_a[np.uint64(m)] - aq)
                        if min(d1, d2) > best:
                            open_r = False
                        else:
                            r1 = ref_r[uj] - rq
                            r2 = ref_r[np.uint64(m)] - rq
                            if r1 * r2 <= 0.0 and abs(d2 - d1) <= math.pi:
                                uu = 0.5 if r1 == r2 else r1 / (r1 - r2)
                                dd = d1 + uu * (d2 - d1)
                                if abs(dd) < best:
                                    best = abs(dd)
                                    d = dd
                                    fm = True
                if open_l:
                    jj = bq - k - 1
                    if jj < 0:
                        jj += n_bins
                    uj = np.uint64(jj)  # unsigned index: no negative-index wraparound code
                    m = nxt[uj]
                    if m >= 0:
                        d1 = _pm_pi(ref_a[uj] - aq)
                        d2 = _pm_pi(ref_a[np.uint64(m)] - aq)
                        if max(d1, d2) < -best:
                            open_l = False
                        else:
                            r1 = ref_r[uj] - rq
                            r2 = ref_r[np.uint64(m)] - rq
                            if r1 * r2 <= 0.0 and abs(d2 - d1) <= math.pi:
                                uu = 0.5 if r1 == r2 else r1 / (r1 - r2)
                                dd = d1 + uu * (d2 - d1)
                                if abs(dd) < best:
                                    best = abs(dd)
                                    d = dd
                                    fm = True
            if fm:
                md[n_m] = d
                mw[n_m] = pr[i] * pr[i]
                n_m += 1
        it += 1
        if n_cp < 3 or n_m < 3:
            break
        dth = _weighted_median(md[:n_m], mw[:n_m])
        th_new = th + dth
        # translation of the closest-point least-squares fit (its own rotation is discarded, as in IDC)
        inv = 1.0 / n_cp
        kxx = sxx - spx * scx * inv
        kxy = sxy - spx * scy * inv
        kyx = syx - spy * scx * inv
        kyy = syy - spy * scy * inv
        om = dm.atan2(kxy - kyx, kxx + kyy)
        co, so = dm.cos(om), dm.sin(om)
        x_new = (scx - (co * spx - so * spy)) * inv
        y_new = (scy - (so * spx + co * spy)) * inv
        dt = math.sqrt((x_new - x) ** 2 + (y_new - y) ** 2)
        x, y, th = x_new, y_new, th_new
        if dt < tol_t and abs(dth) < tol_r:
            converged = True
            break
    return x, y, th, it, converged


@njit(cache=True, error_model="numpy")
def _pairs_point_to_line(px, py, x, y, th, ref_x, ref_y, nxt, cover, seg_ex, seg_ey, seg_il, seg_nx, seg_ny,
                         gate2, max_cp_bins, sin2, h, g, par, hr):
    """Closest-point pairs at pose (x, y, th): fills the point-to-line normal equations h (3x3), g (3) and
    returns (pairs, sum of pair distances). Pairs on an isolated reference point count in the distance but
    not in h, g (no normal). ``hr[q]`` gets the rotation-only normal equation (sum J_th², -sum J_th e) of
    the points of beam parity q (``par``): the two halves of an interlaced scan, see IdcMatcher._learn_skew.
    """
    n = px.shape[0]
    n_bins = ref_x.shape[0]
    inv_res = n_bins / TWO_PI
    c, s = dm.cos(th), dm.sin(th)
    h[:, :] = 0.0
    g[:] = 0.0
    hr[:, :] = 0.0
    pairs = 0
    sd = 0.0
    for i in range(n):
        rx = c * px[i] - s * py[i]
        ry = s * px[i] + c * py[i]
        qx = rx + x
        qy = ry + y
        bq = _bin(fast_atan2(qy, qx), inv_res, n_bins)
        rq2 = qx * qx + qy * qy
        # closest point (see _closest_on_polyline; inlined by hand: a call passing arrays costs an
        # atomic incref/decref per array, more than the search itself)
        best_d2 = gate2
        j = -1
        u = 0.0
        last_r = -2
        last_l = -2
        for k in range(0, max_cp_bins + 1):
            if rq2 * sin2[np.uint64(k)] > best_d2:
                break
            b = bq + k
            if b >= n_bins:
                b -= n_bins
            jj = cover[np.uint64(b)]
            uj = np.uint64(jj)  # unsigned index: no negative-index wraparound code
            if jj >= 0 and jj != last_r:
                last_r = jj
                if k == 0:
                    last_l = jj
                dx = qx - ref_x[uj]
                dy = qy - ref_y[uj]
                uu = min(1.0, max(0.0, (dx * seg_ex[uj] + dy * seg_ey[uj]) * seg_il[uj]))
                dx -= uu * seg_ex[uj]
                dy -= uu * seg_ey[uj]
                dd = dx * dx + dy * dy
                if dd < best_d2:
                    best_d2 = dd
                    j = jj
                    u = uu
            if k == 0:
                continue
            b = bq - k
            if b < 0:
                b += n_bins
            jj = cover[np.uint64(b)]
            uj = np.uint64(jj)  # unsigned index: no negative-index wraparound code
            if jj >= 0 and jj != last_l:
                last_l = jj
                dx = qx - ref_x[uj]
                dy = qy - ref_y[uj]
                uu = min(1.0, max(0.0, (dx * seg_ex[uj] + dy * seg_ey[uj]) * seg_il[uj]))
                dx -= uu * seg_ex[uj]
                dy -= uu * seg_ey[uj]
                dd = dx * dx + dy * dy
                if dd < best_d2:
                    best_d2 = dd
                    j = jj
                    u = uu
        d2 = best_d2
        if j < 0:
            continue
        cx = ref_x[j] + u * seg_ex[j]
        cy = ref_y[j] + u * seg_ey[j]
        pairs += 1
        sd += math.sqrt(d2)
        nx = seg_nx[j]
        ny = seg_ny[j]
        if nx == 0.0 and ny == 0.0:
            continue
        e = nx * (qx - cx) + ny * (qy - cy)
        j2 = rx * ny - ry * nx
        h[0, 0] += nx * nx
        h[0, 1] += nx * ny
        h[0, 2] += nx * j2
        h[1, 1] += ny * ny
        h[1, 2] += ny * j2
        h[2, 2] += j2 * j2
        g[0] -= nx * e
        g[1] -= ny * e
        g[2] -= j2 * e
        q = par[i]
        hr[q, 0] += j2 * j2
        hr[q, 1] -= j2 * e
    h[1, 0] = h[0, 1]
    h[2, 0] = h[0, 2]
    h[2, 1] = h[1, 2]
    return pairs, sd


@njit(cache=True, error_model="numpy")
def polish_point_to_line(px, py, ref_x, ref_y, nxt, cover, seg_ex, seg_ey, seg_il, seg_nx, seg_ny, x0, y0,
                         th0, max_iter, gate, tol_t, tol_r, max_cp_bins, w_t, w_r, par):
    """Gauss-Newton refinement on the closest-point pairs with the point-to-line distance.

    Same correspondences as IDC's closest-point rule (closest point of the polyline within ``gate``), but
    the fit minimises the distance along the segment normal, which does not penalise sliding along a wall:
    it converges in a few iterations where the point-to-point fit creeps. The prediction (0, 0, 0) enters
    as a prior with weights w_t (per axis) and w_r in units of one pair's weight: where the scan cannot
    tell (a corridor, a wall at arm's length) the odometry decides.

    Returns (x, y, th, iterations, pairs, mean pair distance [m], 3x3 point-to-line information, 2x2
    rotation equations per beam parity (see _pairs_point_to_line)), the last four at the pose of the last
    linearisation (within the tolerance of the result when converged).
    """
    n_bins = ref_x.shape[0]
    sin2 = _sin2_table(n_bins, max_cp_bins)
    gate2 = gate * gate
    x = x0
    y = y0
    th = th0
    it = 0
    h = np.zeros((3, 3))
    g = np.zeros(3)
    info = np.zeros((3, 3))
    hr = np.zeros((2, 2))
    pairs = 0
    sd = 0.0
    while it < max_iter:
        pairs, sd = _pairs_point_to_line(px, py, x, y, th, ref_x, ref_y, nxt, cover, seg_ex, seg_ey, seg_il,
                                         seg_nx, seg_ny, gate2, max_cp_bins, sin2, h, g, par, hr)
        for a in range(3):  # element by element: an array slice assignment compiles numba's shape-mismatch
            for b in range(3):  # message (string formatting: 2-3 s of the first run's compilation)
                info[a, b] = h[a, b]
        it += 1
        if pairs < 3:
            break
        h[0, 0] += w_t + 1e-9
        h[1, 1] += w_t + 1e-9
        h[2, 2] += w_r + 1e-9
        g[0] -= w_t * x
        g[1] -= w_t * y
        g[2] -= w_r * th
        step, _ = dm.solve_kernel(h, g)  # h is positive definite (the prior)
        x += step[0]
        y += step[1]
        th += step[2]
        if math.sqrt(step[0] ** 2 + step[1] ** 2) < tol_t and abs(step[2]) < tol_r:
            break
    return x, y, th, it, pairs, (sd / pairs if pairs > 0 else np.inf), info, hr


@njit(cache=True, error_model="numpy")
def match_quality(px, py, x, y, th, ref_x, ref_y, nxt, cover, seg_ex, seg_ey, seg_il, seg_nx, seg_ny, gate,
                  max_cp_bins, par):
    """Closest-point pairs at a pose: (pairs, mean distance [m], 3x3 point-to-line information, 2x2 rotation
    equations per beam parity).

    The information matrix sums J Jᵀ with J = (n, (R p) × n) over the pairs matched to a segment of unit
    normal n; its translational block is near-singular in a featureless corridor (degeneracy test).
    """
    n_bins = ref_x.shape[0]
    sin2 = _sin2_table(n_bins, max_cp_bins)
    h = np.zeros((3, 3))
    g = np.zeros(3)
    hr = np.zeros((2, 2))
    pairs, sd = _pairs_point_to_line(px, py, x, y, th, ref_x, ref_y, nxt, cover, seg_ex, seg_ey, seg_il,
                                     seg_nx, seg_ny, gate * gate, max_cp_bins, sin2, h, g, par, hr)
    return pairs, (sd / pairs if pairs > 0 else np.inf), h, hr


@njit(cache=True, error_model="numpy")
def coarse_rotation(pa, pr, ref_r, ok, half_bins, step_bins, every, tol_abs, tol_rel):
    """Correlative rotation search: the rotation of the scan about the reference origin whose range
    profile agrees best with the reference's, over +-``half_bins`` bins in steps of ``step_bins``.

    A scan point of bearing a and range r is *covered* at rotation d when one of the bins around a + d holds
    a reference point, and *agrees* when r is within tol_abs + tol_rel r of the range interval of those.
    The score is the fraction of covered points that agree (at least half the points covered): counting
    agreeing points
    alone would favour the rotation that overlaps the map most, in a round hall any rotation back towards
    the map. Unlike IDC, which follows the gradient of its bearing window, this sees the whole window at
    once: it finds the basin, IDC aligns in it. Uses every ``every``-th point.

    Returns (best rotation [rad], its score, the score at rotation 0); ties go to the smallest rotation.
    """
    n_bins = ref_r.shape[0]
    inv_res = n_bins / TWO_PI
    n_s = 2 * (half_bins // step_bins) + 1
    # the range interval of the reference over bins b-1..b+1 (empty: lo > hi), so that each (point,
    # rotation) is one lookup; a point agrees when its range is within tolerance of that interval
    lo = np.full(n_bins, np.inf)
    hi = np.full(n_bins, -np.inf)
    for b in range(n_bins):
        if ok[b]:
            r = ref_r[b]
            for db in range(-1, 2):
                bb = b + db
                if bb < 0:
                    bb += n_bins
                elif bb >= n_bins:
                    bb -= n_bins
                lo[bb] = min(lo[bb], r)
                hi[bb] = max(hi[bb], r)
    hits = np.zeros(n_s)
    cov = np.zeros(n_s)
    n_pts = 0
    for i in range(0, pa.shape[0], every):
        n_pts += 1
        r = pr[i]
        tol = tol_abs + tol_rel * r
        b0 = _bin(pa[i], inv_res, n_bins) - (n_s // 2) * step_bins
        for k in range(n_s):
            b = b0 + k * step_bins
            if b < 0:
                b += n_bins
            elif b >= n_bins:
                b -= n_bins
            seen = lo[b] <= hi[b]
            cov[k] += 1.0 if seen else 0.0
            hits[k] += 1.0 if (seen and r > lo[b] - tol and r < hi[b] + tol) else 0.0
    score = np.zeros(n_s)
    for k in range(n_s):
        if cov[k] >= 0.5 * n_pts and cov[k] > 0.0:
            score[k] = hits[k] / cov[k]
    c = n_s // 2
    best = c
    for d in range(1, c + 1):
        if score[c + d] > score[best]:
            best = c + d
        if score[c - d] > score[best]:
            best = c - d
    return (best - c) * step_bins * TWO_PI / n_bins, score[best], score[c]


@njit(cache=True, error_model="numpy")
def _idc_polish(px, py, pr, ref_x, ref_y, ref_r, ref_a, ok, nxt, cover, ex, ey, il, nx, ny, unseen, th0,
                max_iter, win0, win_tau, win_min, gate0, gate_min, tol_t, tol_r, max_cp_bins, stride,
                mrp_every, polish_iter, w_t, w_r, par):
    """IDC from rotation ``th0``, then the point-to-line polish (``polish_iter`` > 0) or just the quality of
    the IDC pose: (x, y, th, iterations, pairs, mean pair distance, 3x3 information, 2x2 rotation equations
    per beam parity)."""
    x, y, th, iters, _ = idc_align(px, py, pr, ref_x, ref_y, ref_r, ref_a, ok, nxt, cover, ex, ey, il, unseen,
                                   0.0, 0.0, th0, max_iter, win0, win_tau, win_min, gate0, gate_min, tol_t,
                                   tol_r, max_cp_bins, stride, mrp_every)
    if polish_iter > 0:
        x, y, th, it2, pairs, resid, info, hr = polish_point_to_line(px, py, ref_x, ref_y, nxt, cover, ex, ey,
                                                                     il, nx, ny, x, y, th, polish_iter,
                                                                     gate_min, tol_t, tol_r, max_cp_bins, w_t,
                                                                     w_r, par)
        return x, y, th, iters + it2, pairs, resid, info, hr
    pairs, resid, info, hr = match_quality(px, py, x, y, th, ref_x, ref_y, nxt, cover, ex, ey, il, nx, ny,
                                           gate_min, max_cp_bins, par)
    return x, y, th, iters, pairs, resid, info, hr


@njit(cache=True, error_model="numpy")
def match_scan(kf_xy, kf_n, kf_view, ox, oy, oth, px, py, pr, n_bins, min_r, max_r, blend_m, seg_abs_m,
               seg_rel, gap_bins, normal_chord_m, max_iter, win0, win_tau, win_min, gate0, gate_min, tol_t,
               tol_r, max_cp_bins, stride, mrp_every, polish_iter, w_t, w_r, pa, coarse_bins, coarse_step,
               coarse_every, coarse_tol_abs, coarse_tol_rel, coarse_min_gain, coarse_margin, par):
    """The whole match in one call (one dispatch instead of four): render the reference at (ox, oy, oth),
    its segments and the ends no keyframe saw past (``kf_view``, see unseen_ends), IDC from the prediction,
    then the point-to-line polish (``polish_iter`` > 0) or just the quality of the IDC pose. With
    ``coarse_bins`` > 0, a second IDC may start from the rotation that the correlative search
    (coarse_rotation) prefers (see the comment below).

    Returns (x, y, th, iterations, pairs, mean pair distance [m], 3x3 point-to-line information, smallest
    eigenvalue of its translational 2x2 block, rotation of the odd beams' half-scan against the map minus
    the even beams' one [rad] (nan when a half constrains no rotation; ``par`` gives each point's parity)).
    """
    ref_x, ref_y, ref_r, ref_a, ok, nxt = render_reference(kf_xy, kf_n, ox, oy, oth, n_bins, min_r, max_r,
                                                           blend_m, seg_abs_m, seg_rel, gap_bins)
    ex, ey, il, nx, ny, cover = segments(ref_x, ref_y, ok, nxt, normal_chord_m)
    unseen = unseen_ends(ref_x, ref_y, nxt, kf_view, kf_n, ox, oy, oth)
    x, y, th, iters, pairs, resid, info, hr = _idc_polish(
        px, py, pr, ref_x, ref_y, ref_r, ref_a, ok, nxt, cover, ex, ey, il, nx, ny, unseen, 0.0, max_iter,
        win0, win_tau, win_min, gate0, gate_min, tol_t, tol_r, max_cp_bins, stride, mrp_every, polish_iter,
        w_t, w_r, par)
    if coarse_bins > 0:
        # IDC only follows its bearing window: when the correlative search sees a rotation that agrees
        # better elsewhere in the window, IDC starts from there too, and that match wins when its mean
        # truncated pair distance (gate_min for an unpaired point) is lower by coarse_margin
        th1, s1, s0 = coarse_rotation(pa, pr, ref_r, ok, coarse_bins, coarse_step, coarse_every,
                                      coarse_tol_abs, coarse_tol_rel)
        if s1 >= s0 + coarse_min_gain and abs(_pm_pi(th1 - th)) > 2.0 * win_min:
            x2, y2, t2, it2, p2, r2, i2, hr2 = _idc_polish(
                px, py, pr, ref_x, ref_y, ref_r, ref_a, ok, nxt, cover, ex, ey, il, nx, ny, unseen, th1,
                max_iter, win0, win_tau, win_min, gate0, gate_min, tol_t, tol_r, max_cp_bins, stride,
                mrp_every, polish_iter, w_t, w_r, par)
            iters += it2
            n = px.shape[0]
            cost1 = (resid * pairs + gate_min * (n - pairs)) / n
            cost2 = (r2 * p2 + gate_min * (n - p2)) / n
            if cost2 < (1.0 - coarse_margin) * cost1:
                x, y, th, pairs, resid, info, hr = x2, y2, t2, p2, r2, i2, hr2
    # smallest eigenvalue of the symmetric 2x2 block [[a, b], [b, c]]
    a = info[0, 0]
    b = info[0, 1]
    c = info[1, 1]
    hm = 0.5 * (a - c)
    weakest = 0.5 * (a + c) - math.sqrt(hm * hm + b * b)
    # rotation-only Gauss-Newton step of each half (g / h): how much each half would still turn alone
    half_rot = np.nan
    if hr[0, 0] > 0.0 and hr[1, 0] > 0.0:
        half_rot = hr[1, 1] / hr[1, 0] - hr[0, 1] / hr[0, 0]
    return x, y, th, iters, pairs, resid, info, weakest, half_rot
