"""Numba kernels of the IDC matcher: render the local map as a reference scan, then iterate IDC.

Frames: the *reference frame* is the predicted laser pose (odometry prior) at which the map is rendered. The
estimate (x, y, th) is the pose of the new scan's laser in that frame; the IDC loop starts at (0, 0, 0).
The reference scan has ``n_bins`` bearing bins over the full circle, bin b covering
[-pi + b * res, -pi + (b + 1) * res), so bin indices wrap around.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def _wrap(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return a - TWO_PI * math.floor((a + math.pi) / TWO_PI)


@njit(cache=True)
def _bin(a: float, inv_res: float, n_bins: int) -> int:
    b = int((a + math.pi) * inv_res)
    if b < 0:
        return 0
    if b >= n_bins:
        return n_bins - 1
    return b


@njit(cache=True)
def render_reference(kf_xy, kf_n, ox, oy, oth, n_bins, min_r, max_r, blend_m,
                     seg_abs_m, seg_rel, gap_bins):
    """Render the keyframe points (world frame) as a polar reference scan seen from pose (ox, oy, oth).

    Per bearing bin the nearest return wins (occlusion), and the points within ``blend_m`` behind it are
    averaged with it (several keyframes see the same wall: averaging cuts their noise). ``nxt[b]`` is the next
    valid bin after b (within ``gap_bins``) that continues the same surface, else -1: the polyline the IDC
    rules interpolate along never bridges a depth discontinuity.

    Returns (ref_x, ref_y, ok, nxt) in the reference frame, each of length n_bins.
    """
    inv_res = n_bins / TWO_PI
    c, s = math.cos(oth), math.sin(oth)
    rmin = np.full(n_bins, np.inf)
    n_kf = kf_n.shape[0]
    total = 0
    for k in range(n_kf):
        total += kf_n[k]
    lx = np.empty(total)
    ly = np.empty(total)
    lr = np.empty(total)
    lb = np.empty(total, dtype=np.int64)
    m = 0
    for k in range(n_kf):
        for i in range(kf_n[k]):
            dx = kf_xy[k, i, 0] - ox
            dy = kf_xy[k, i, 1] - oy
            x = c * dx + s * dy
            y = -s * dx + c * dy
            r = math.sqrt(x * x + y * y)
            if r < min_r or r > max_r:
                continue
            b = _bin(math.atan2(y, x), inv_res, n_bins)
            lx[m] = x
            ly[m] = y
            lr[m] = r
            lb[m] = b
            if r < rmin[b]:
                rmin[b] = r
            m += 1
    sx = np.zeros(n_bins)
    sy = np.zeros(n_bins)
    cnt = np.zeros(n_bins)
    for i in range(m):
        b = lb[i]
        if lr[i] <= rmin[b] + blend_m:
            sx[b] += lx[i]
            sy[b] += ly[i]
            cnt[b] += 1.0
    ref_x = np.zeros(n_bins)
    ref_y = np.zeros(n_bins)
    ok = cnt > 0.0
    for b in range(n_bins):
        if ok[b]:
            ref_x[b] = sx[b] / cnt[b]
            ref_y[b] = sy[b] / cnt[b]
    nxt = np.full(n_bins, -1, dtype=np.int64)
    for b in range(n_bins):
        if not ok[b]:
            continue
        for g in range(1, gap_bins + 1):
            j = (b + g) % n_bins
            if ok[j]:
                dx = ref_x[j] - ref_x[b]
                dy = ref_y[j] - ref_y[b]
                lim = seg_abs_m + seg_rel * max(rmin[b], rmin[j]) * g
                if dx * dx + dy * dy <= lim * lim:
                    nxt[b] = j
                break
    return ref_x, ref_y, ok, nxt


@njit(cache=True)
def _closest_on_polyline(qx, qy, bq, w_max, gap_bins, ref_x, ref_y, ok, nxt, best_d2):
    """Closest point to (qx, qy) on the reference polyline, searching outwards from bin bq.

    A segment or point whose bearing differs from q's by delta is at least |q| sin(delta) away, so the
    search stops as soon as that bound exceeds the best distance (segments start up to ``gap_bins`` bins
    before the bearing they reach). ``best_d2`` is the squared gate. Returns (found, cx, cy, nx, ny, d2)
    with (nx, ny) the unit normal of the matched segment ((0, 0) when matched to an isolated point).
    """
    n_bins = ref_x.shape[0]
    res = TWO_PI / n_bins
    rq = math.sqrt(qx * qx + qy * qy)
    found = False
    cx = 0.0
    cy = 0.0
    nx = 0.0
    ny = 0.0
    for k in range(0, w_max + 1):
        dk = (k - gap_bins - 1) * res
        if dk > 0.0 and (dk >= 0.5 * math.pi or rq * math.sin(dk) > math.sqrt(best_d2)):
            break
        for side in range(2):
            if k == 0 and side == 1:
                continue
            j = (bq + k) % n_bins if side == 0 else (bq - k) % n_bins
            if not ok[j]:
                continue
            ax = ref_x[j]
            ay = ref_y[j]
            m = nxt[j]
            if m >= 0:
                ex = ref_x[m] - ax
                ey = ref_y[m] - ay
                ll = ex * ex + ey * ey
                u = ((qx - ax) * ex + (qy - ay) * ey) / ll if ll > 0.0 else 0.0
                u = min(1.0, max(0.0, u))
                px = ax + u * ex
                py = ay + u * ey
                d2 = (qx - px) ** 2 + (qy - py) ** 2
                if d2 < best_d2:
                    best_d2 = d2
                    cx = px
                    cy = py
                    inv = 1.0 / math.sqrt(ll) if ll > 0.0 else 0.0
                    nx = -ey * inv
                    ny = ex * inv
                    found = True
            else:
                d2 = (qx - ax) ** 2 + (qy - ay) ** 2
                if d2 < best_d2:
                    best_d2 = d2
                    cx = ax
                    cy = ay
                    nx = 0.0
                    ny = 0.0
                    found = True
    return found, cx, cy, nx, ny, best_d2


@njit(cache=True)
def _polar(j, x, y, th, ref_x, ref_y, rho, alpha, stamp, it):
    """Range and bearing of reference bin j about the current scan origin, cached per iteration."""
    if stamp[j] != it:
        dx = ref_x[j] - x
        dy = ref_y[j] - y
        rho[j] = math.sqrt(dx * dx + dy * dy)
        alpha[j] = math.atan2(dy, dx) - th
        stamp[j] = it


@njit(cache=True)
def _matching_range(r, phi, bq, bw, extra, x, y, th, ref_x, ref_y, ok, nxt, rho, alpha, stamp, it):
    """Matching-range-point rule: bearing offset d (|d| <= bw, smallest) where the reference polyline has
    range r about the scan origin. Searches outwards from bin bq; bearings of the reference are monotonic in
    the bin index up to ``extra`` (the scan origin is off the reference origin). Returns (found, d, slope)
    with slope = d(range)/d(bearing) of the reference there [m/rad]."""
    n_bins = ref_x.shape[0]
    res = TWO_PI / n_bins
    w_max = min(n_bins // 2 - 1, int((bw + extra) / res) + 2)
    best = bw
    dbest = 0.0
    slope = 0.0
    found = False
    for side in range(2):
        for k in range(0, w_max + 1):
            j = (bq + k) % n_bins if side == 0 else (bq - k - 1) % n_bins
            if not ok[j]:
                continue
            m = nxt[j]
            if m < 0:
                continue
            _polar(j, x, y, th, ref_x, ref_y, rho, alpha, stamp, it)
            _polar(m, x, y, th, ref_x, ref_y, rho, alpha, stamp, it)
            d1 = _wrap(alpha[j] - phi)
            d2 = _wrap(alpha[m] - phi)
            if abs(d2 - d1) > math.pi:
                continue
            if side == 0 and min(d1, d2) > best + extra:
                break
            if side == 1 and max(d1, d2) < -(best + extra):
                break
            r1 = rho[j] - r
            r2 = rho[m] - r
            if r1 * r2 > 0.0:
                continue
            u = 0.5 if r1 == r2 else r1 / (r1 - r2)
            d = d1 + u * (d2 - d1)
            if abs(d) < best:
                best = abs(d)
                dbest = d
                slope = (rho[m] - rho[j]) / (d2 - d1) if d2 != d1 else 0.0
                found = True
    return found, dbest, slope


@njit(cache=True)
def _weighted_median(v, w):
    """Weighted median of v (robust location of the matching-range-point bearing offsets)."""
    order = np.argsort(v)
    half = 0.5 * np.sum(w)
    acc = 0.0
    for k in range(order.shape[0]):
        acc += w[order[k]]
        if acc >= half:
            return v[order[k]]
    return v[order[-1]]


@njit(cache=True)
def idc_align(px, py, pr, pa, ref_x, ref_y, ok, nxt, max_iter, win0, win_tau, win_min,
              gate0, gate_min, tol_t, tol_r, max_cp_bins, gap_bins, mrp_stride, sigma_r, sigma_a,
              robust_rot, fit):
    """Iterative Dual Correspondence (Lu & Milios 1997) of points (px, py) against the reference polyline.

    Each iteration pairs every point twice: the closest point on the polyline (gated by a distance that
    shrinks from gate0 to gate_min) gives the translation, the point of equal range in the angular window
    [phi - Bw, phi + Bw] (Bw shrinking from win0 to win_min) gives the rotation (every ``mrp_stride``-th
    point only: the rule is the expensive one and the rotation needs fewer points). The rotation is the
    range²-weighted mean of the matching-range-point bearing offsets (the least-squares rotation about the
    scan origin); the translation is the least-squares translation of the closest-point pairs at that
    rotation.

    Returns (x, y, th, iterations, converged).
    """
    n = px.shape[0]
    n_bins = ref_x.shape[0]
    inv_res = n_bins / TWO_PI
    x = 0.0
    y = 0.0
    th = 0.0
    rho = np.zeros(n_bins)
    alpha = np.zeros(n_bins)
    stamp = np.full(n_bins, -1, dtype=np.int64)
    md = np.empty(n)
    mw = np.empty(n)
    var_r = sigma_r * sigma_r
    var_a = sigma_a * sigma_a
    it = 0
    converged = False
    while it < max_iter:
        bw = max(win_min, win0 * math.exp(-it / win_tau))
        gate = max(gate_min, gate0 * math.exp(-it / win_tau))
        c, s = math.cos(th), math.sin(th)
        t_norm = math.sqrt(x * x + y * y)
        sw = 0.0
        swd = 0.0
        hh = np.zeros((3, 3))
        bb_ = np.zeros(3)
        a11 = 0.0; a12 = 0.0; a22 = 0.0; b1 = 0.0; b2 = 0.0
        g11 = 0.0; g12 = 0.0; g21 = 0.0; g22 = 0.0
        pp_x = 0.0; pp_y = 0.0; n_pp = 0
        m11 = 0.0; m12 = 0.0; m21 = 0.0; m22 = 0.0; m31 = 0.0; m32 = 0.0
        n_m = 0
        n_cp = 0
        spx = 0.0
        spy = 0.0
        scx = 0.0
        scy = 0.0
        for i in range(n):
            qx = c * px[i] - s * py[i] + x
            qy = s * px[i] + c * py[i] + y
            bq = _bin(math.atan2(qy, qx), inv_res, n_bins)
            f, cx, cy, nx, ny, _ = _closest_on_polyline(qx, qy, bq, max_cp_bins, gap_bins, ref_x, ref_y, ok,
                                                        nxt, gate * gate)
            if fit == 1:
                if f and (nx != 0.0 or ny != 0.0):
                    e = nx * (qx - cx) + ny * (qy - cy)
                    jr = (qx - x) * ny - (qy - y) * nx
                    jv = (nx, ny, jr)
                    for aa in range(3):
                        bb_[aa] -= jv[aa] * e
                        for bb in range(3):
                            hh[aa, bb] += jv[aa] * jv[bb]
                    n_cp += 1
                continue
            if f and fit == 2:
                if nx == 0.0 and ny == 0.0:
                    # matched to an isolated point: point-to-point (both directions constrained)
                    a11 += 1.0
                    a22 += 1.0
                    b1 += cx
                    b2 += cy
                    g11 += px[i]; g12 += py[i]; g21 += 0.0; g22 += 0.0
                    # store for rotation-dependent rhs below
                    pp_x += px[i]; pp_y += py[i]; n_pp += 1
                else:
                    a11 += nx * nx
                    a12 += nx * ny
                    a22 += ny * ny
                    nc = nx * cx + ny * cy
                    b1 += nx * nc
                    b2 += ny * nc
                    # rhs part depending on rotation: n (n . R p): keep sums of n n^T p
                    m11 += nx * nx * px[i]; m12 += nx * nx * py[i]
                    m21 += nx * ny * px[i]; m22 += nx * ny * py[i]
                    m31 += ny * ny * px[i]; m32 += ny * ny * py[i]
                n_cp += 1
            elif f:
                n_cp += 1
                spx += px[i]
                spy += py[i]
                scx += cx
                scy += cy
            if i % mrp_stride != 0:
                continue
            extra = math.asin(min(1.0, t_norm / max(pr[i], 1e-9)))
            fm, d, slope = _matching_range(pr[i], pa[i], bq, bw, extra, x, y, th, ref_x, ref_y, ok, nxt,
                                           rho, alpha, stamp, it)
            if fm:
                if var_r > 0.0:
                    wgt = slope * slope / (var_r + var_a * slope * slope)
                else:
                    wgt = pr[i] * pr[i]
                sw += wgt
                swd += wgt * d
                md[n_m] = d
                mw[n_m] = wgt
                n_m += 1
        it += 1
        if fit == 1:
            if n_cp < 3:
                break
            sol = np.linalg.solve(hh + 1e-9 * np.eye(3), bb_)
            x += sol[0]
            y += sol[1]
            th += sol[2]
            if math.sqrt(sol[0] ** 2 + sol[1] ** 2) < tol_t and abs(sol[2]) < tol_r:
                converged = True
                break
            continue
        if n_cp < 3 or sw <= 0.0:
            break
        if robust_rot:
            dth = _weighted_median(md[:n_m], mw[:n_m])
        else:
            dth = swd / sw
        th_new = th + dth
        c2, s2 = math.cos(th_new), math.sin(th_new)
        if fit == 2:
            # sum n n^T R p = [ [nx², nxny], [nxny, ny²] ] R p
            # R p = (c2 px - s2 py, s2 px + c2 py)
            t11 = c2 * m11 - s2 * m12  # sum nx² (Rp)_x
            t12 = s2 * m11 + c2 * m12  # sum nx² (Rp)_y
            t21 = c2 * m21 - s2 * m22  # sum nxny (Rp)_x
            t22 = s2 * m21 + c2 * m22  # sum nxny (Rp)_y
            t31 = c2 * m31 - s2 * m32  # sum ny² (Rp)_x
            t32 = s2 * m31 + c2 * m32  # sum ny² (Rp)_y
            r1 = b1 - (t11 + t22) - (c2 * pp_x - s2 * pp_y)
            r2 = b2 - (t21 + t32) - (s2 * pp_x + c2 * pp_y)
            lam = 1e-3 * (a11 + a22) + 1e-9
            r1 += lam * x
            r2 += lam * y
            d11 = a11 + lam
            d22 = a22 + lam
            det = d11 * d22 - a12 * a12
            x_new = (d22 * r1 - a12 * r2) / det
            y_new = (d11 * r2 - a12 * r1) / det
        else:
            inv = 1.0 / n_cp
            x_new = scx * inv - (c2 * spx - s2 * spy) * inv
            y_new = scy * inv - (s2 * spx + c2 * spy) * inv
        dt = math.sqrt((x_new - x) ** 2 + (y_new - y) ** 2)
        x, y, th = x_new, y_new, th_new
        if dt < tol_t and abs(dth) < tol_r:
            converged = True
            break
    return x, y, th, it, converged


@njit(cache=True)
def match_quality(px, py, x, y, th, ref_x, ref_y, ok, nxt, gate, max_cp_bins, gap_bins):
    """Closest-point pairs at the final estimate: (pairs, mean distance [m], 3x3 point-to-line information).

    The information matrix sums J Jᵀ with J = (n, (R p) × n) over pairs matched to a segment of normal n; its
    translational block is near-singular in a featureless corridor (degeneracy test).
    """
    n = px.shape[0]
    n_bins = ref_x.shape[0]
    inv_res = n_bins / TWO_PI
    c, s = math.cos(th), math.sin(th)
    info = np.zeros((3, 3))
    pairs = 0
    sd = 0.0
    for i in range(n):
        rx = c * px[i] - s * py[i]
        ry = s * px[i] + c * py[i]
        qx = rx + x
        qy = ry + y
        bq = _bin(math.atan2(qy, qx), inv_res, n_bins)
        f, _, _, nx, ny, d2 = _closest_on_polyline(qx, qy, bq, max_cp_bins, gap_bins, ref_x, ref_y, ok, nxt,
                                                   gate * gate)
        if not f:
            continue
        pairs += 1
        sd += math.sqrt(d2)
        jr = rx * ny - ry * nx
        jv = (nx, ny, jr)
        for a in range(3):
            for b in range(3):
                info[a, b] += jv[a] * jv[b]
    return pairs, (sd / pairs if pairs > 0 else np.inf), info
