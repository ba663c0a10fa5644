"""ORCA (van den Berg et al. 2011) computed exactly as the RVO2 library's ``doStep`` computes new velocities.

The algorithm follows RVO2 step by step so that results agree with it to float precision: neighbours are the
``max_neighbors`` nearest agents strictly within ``neighbor_dist`` (sorted by distance), each contributes one
ORCA half-plane (velocity obstacle truncated at ``time_horizon``, or the ``dt`` disc when already overlapping),
the 2-D incremental linear program finds the velocity closest to the preferred one inside the speed disc, and
the 3-D linear program minimises the largest violation when the half-planes have no common point.

Everything runs in numba over a batch of worlds: one call steps ``B`` worlds of ``n`` agents.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike

# RVO2 computes in single precision, and its 3-D program is ill-conditioned enough that double precision can
# land on a different vertex; float32 throughout (constants included), and division by a scalar as a multiplication
# by its reciprocal as RVO2's Vector2 does it, reproduce it.
RVO_EPSILON = np.float32(1e-5)
HALF = np.float32(0.5)
ONE = np.float32(1.0)

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _det(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


@_jit
def _lp1(
    lp: np.ndarray,
    ld_x: np.ndarray,
    ld_y: np.ndarray,
    line_no: int,
    radius: float,
    opt_x: float,
    opt_y: float,
    direction_opt: bool,
    result: np.ndarray,
) -> bool:
    """Optimise on line ``line_no`` subject to lines before it and the speed disc; False when infeasible."""
    px, py = lp[line_no, 0], lp[line_no, 1]
    dx, dy = ld_x[line_no], ld_y[line_no]
    dot = px * dx + py * dy
    discriminant = dot * dot + radius * radius - (px * px + py * py)
    if discriminant < 0.0:
        return False
    sqrt_disc = np.sqrt(discriminant)
    t_left = -dot - sqrt_disc
    t_right = -dot + sqrt_disc
    for i in range(line_no):
        denominator = _det(dx, dy, ld_x[i], ld_y[i])
        numerator = _det(ld_x[i], ld_y[i], px - lp[i, 0], py - lp[i, 1])
        if abs(denominator) <= RVO_EPSILON:
            if numerator < 0.0:
                return False
            continue
        t = numerator / denominator
        if denominator >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return False
    if direction_opt:
        t = t_right if opt_x * dx + opt_y * dy > 0.0 else t_left
    else:
        t = dx * (opt_x - px) + dy * (opt_y - py)
        if t < t_left:
            t = t_left
        elif t > t_right:
            t = t_right
    result[0] = px + t * dx
    result[1] = py + t * dy
    return True


@_jit
def _lp2(
    lp: np.ndarray,
    ld_x: np.ndarray,
    ld_y: np.ndarray,
    n_lines: int,
    radius: float,
    opt_x: float,
    opt_y: float,
    direction_opt: bool,
    result: np.ndarray,
) -> int:
    """Closest point to the optimum inside all half-planes and the disc; returns the first failing line."""
    if direction_opt:
        result[0] = opt_x * radius
        result[1] = opt_y * radius
    elif opt_x * opt_x + opt_y * opt_y > radius * radius:
        inv_norm = ONE / np.sqrt(opt_x * opt_x + opt_y * opt_y)
        result[0] = opt_x * inv_norm * radius
        result[1] = opt_y * inv_norm * radius
    else:
        result[0] = opt_x
        result[1] = opt_y
    for i in range(n_lines):
        if _det(ld_x[i], ld_y[i], lp[i, 0] - result[0], lp[i, 1] - result[1]) > 0.0:
            keep_x, keep_y = result[0], result[1]
            if not _lp1(lp, ld_x, ld_y, i, radius, opt_x, opt_y, direction_opt, result):
                result[0], result[1] = keep_x, keep_y
                return i
    return n_lines


@_jit
def _lp3(
    lp: np.ndarray,
    ld_x: np.ndarray,
    ld_y: np.ndarray,
    n_lines: int,
    begin_line: int,
    radius: float,
    result: np.ndarray,
    proj_p: np.ndarray,
    proj_dx: np.ndarray,
    proj_dy: np.ndarray,
) -> None:
    """Minimise the largest violation of the half-planes from ``begin_line`` on (the 3-D fallback)."""
    distance = 0.0
    for i in range(begin_line, n_lines):
        if _det(ld_x[i], ld_y[i], lp[i, 0] - result[0], lp[i, 1] - result[1]) > distance:
            n_proj = 0
            for j in range(i):
                determinant = _det(ld_x[i], ld_y[i], ld_x[j], ld_y[j])
                if abs(determinant) <= RVO_EPSILON:
                    if ld_x[i] * ld_x[j] + ld_y[i] * ld_y[j] > 0.0:
                        continue
                    proj_p[n_proj, 0] = HALF * (lp[i, 0] + lp[j, 0])
                    proj_p[n_proj, 1] = HALF * (lp[i, 1] + lp[j, 1])
                else:
                    s = _det(ld_x[j], ld_y[j], lp[i, 0] - lp[j, 0], lp[i, 1] - lp[j, 1]) / determinant
                    proj_p[n_proj, 0] = lp[i, 0] + s * ld_x[i]
                    proj_p[n_proj, 1] = lp[i, 1] + s * ld_y[i]
                ddx = ld_x[j] - ld_x[i]
                ddy = ld_y[j] - ld_y[i]
                inv_norm = ONE / np.sqrt(ddx * ddx + ddy * ddy)
                proj_dx[n_proj] = ddx * inv_norm
                proj_dy[n_proj] = ddy * inv_norm
                n_proj += 1
            keep_x, keep_y = result[0], result[1]
            if _lp2(proj_p, proj_dx, proj_dy, n_proj, radius, -ld_y[i], ld_x[i], True, result) < n_proj:
                result[0], result[1] = keep_x, keep_y
            distance = _det(ld_x[i], ld_y[i], lp[i, 0] - result[0], lp[i, 1] - result[1])


@_jit
def _agent_velocity(
    pos: np.ndarray,
    vel: np.ndarray,
    pref: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    a: int,
    neighbor_dist: np.float32,
    max_neighbors: int,
    inv_horizon: np.float32,
    dt: np.float32,
    out: np.ndarray,
    nb_idx: np.ndarray,
    nb_dist: np.ndarray,
    lp: np.ndarray,
    ld_x: np.ndarray,
    ld_y: np.ndarray,
    proj_p: np.ndarray,
    proj_dx: np.ndarray,
    proj_dy: np.ndarray,
) -> None:
    """New velocity of agent ``a`` of one world, written to ``out``."""
    n = pos.shape[0]
    # Nearest neighbours, ascending distance, as RVO2's kd-tree insertion keeps them.
    range_sq = neighbor_dist * neighbor_dist
    count = 0
    for b in range(n):
        if b == a:
            continue
        rx = pos[a, 0] - pos[b, 0]
        ry = pos[a, 1] - pos[b, 1]
        dist_sq = rx * rx + ry * ry
        if dist_sq < range_sq:
            if count < max_neighbors:
                count += 1
            k = count - 1
            while k != 0 and dist_sq < nb_dist[k - 1]:
                nb_dist[k] = nb_dist[k - 1]
                nb_idx[k] = nb_idx[k - 1]
                k -= 1
            nb_dist[k] = dist_sq
            nb_idx[k] = b
            if count == max_neighbors:
                range_sq = nb_dist[count - 1]

    inv_dt = ONE / dt
    for k in range(count):
        b = nb_idx[k]
        rpx = pos[b, 0] - pos[a, 0]
        rpy = pos[b, 1] - pos[a, 1]
        rvx = vel[a, 0] - vel[b, 0]
        rvy = vel[a, 1] - vel[b, 1]
        dist_sq = rpx * rpx + rpy * rpy
        combined_radius = radii[a] + radii[b]
        combined_radius_sq = combined_radius * combined_radius
        if dist_sq > combined_radius_sq:
            wx = rvx - inv_horizon * rpx
            wy = rvy - inv_horizon * rpy
            w_len_sq = wx * wx + wy * wy
            dot1 = wx * rpx + wy * rpy
            if dot1 < 0.0 and dot1 * dot1 > combined_radius_sq * w_len_sq:
                w_len = np.sqrt(w_len_sq)
                inv_w_len = ONE / w_len
                ux_unit = wx * inv_w_len
                uy_unit = wy * inv_w_len
                dx = uy_unit
                dy = -ux_unit
                ux = (combined_radius * inv_horizon - w_len) * ux_unit
                uy = (combined_radius * inv_horizon - w_len) * uy_unit
            else:
                leg = np.sqrt(dist_sq - combined_radius_sq)
                inv_dist_sq = ONE / dist_sq
                if _det(rpx, rpy, wx, wy) > 0.0:
                    dx = (rpx * leg - rpy * combined_radius) * inv_dist_sq
                    dy = (rpx * combined_radius + rpy * leg) * inv_dist_sq
                else:
                    dx = -(rpx * leg + rpy * combined_radius) * inv_dist_sq
                    dy = -(-rpx * combined_radius + rpy * leg) * inv_dist_sq
                dot2 = rvx * dx + rvy * dy
                ux = dot2 * dx - rvx
                uy = dot2 * dy - rvy
        else:
            wx = rvx - inv_dt * rpx
            wy = rvy - inv_dt * rpy
            w_len = np.sqrt(wx * wx + wy * wy)
            inv_w_len = ONE / w_len
            ux_unit = wx * inv_w_len
            uy_unit = wy * inv_w_len
            dx = uy_unit
            dy = -ux_unit
            ux = (combined_radius * inv_dt - w_len) * ux_unit
            uy = (combined_radius * inv_dt - w_len) * uy_unit
        lp[k, 0] = vel[a, 0] + HALF * ux
        lp[k, 1] = vel[a, 1] + HALF * uy
        ld_x[k] = dx
        ld_y[k] = dy

    fail = _lp2(lp, ld_x, ld_y, count, max_speeds[a], pref[a, 0], pref[a, 1], False, out)
    if fail < count:
        _lp3(lp, ld_x, ld_y, count, fail, max_speeds[a], out, proj_p, proj_dx, proj_dy)


@_jit
def _solve_world(
    pos: np.ndarray,
    vel: np.ndarray,
    pref: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    n_ego: int,
    neighbor_dist: np.float32,
    max_neighbors: int,
    time_horizon: np.float32,
    dt: np.float32,
    out: np.ndarray,
) -> None:
    """New velocities of the first ``n_ego`` agents of one world (float32 arrays) into ``out``."""
    n = pos.shape[0]
    inv_horizon = ONE / time_horizon
    nb_idx = np.empty(n, np.int64)
    nb_dist = np.empty(n, np.float32)
    lp = np.empty((n, 2), np.float32)
    ld_x = np.empty(n, np.float32)
    ld_y = np.empty(n, np.float32)
    proj_p = np.empty((n, 2), np.float32)
    proj_dx = np.empty(n, np.float32)
    proj_dy = np.empty(n, np.float32)
    for a in range(n_ego):
        _agent_velocity(
            pos,
            vel,
            pref,
            radii,
            max_speeds,
            a,
            neighbor_dist,
            max_neighbors,
            inv_horizon,
            dt,
            out[a],
            nb_idx,
            nb_dist,
            lp,
            ld_x,
            ld_y,
            proj_p,
            proj_dx,
            proj_dy,
        )


@_jit
def _crowd_world(
    pos: np.ndarray,
    vel: np.ndarray,
    goal: np.ndarray,
    radii: np.ndarray,
    v_pref: np.ndarray,
    pref_offset: np.ndarray,
    padding: np.float32,
    neighbor_dist: np.float32,
    max_neighbors: int,
    time_horizon: np.float32,
    dt: np.float32,
    out: np.ndarray,
) -> None:
    """One crowd as CrowdNav drives RVO2: the preferred velocity is the vector to the goal, normalised only
    when longer than 1 m, plus ``pref_offset``; radii padded by ``padding``; speed limit v_pref."""
    n = pos.shape[0]
    p = np.empty((n, 2), np.float32)
    v = np.empty((n, 2), np.float32)
    pref = np.empty((n, 2), np.float32)
    rad = np.empty(n, np.float32)
    speed = np.empty(n, np.float32)
    for i in range(n):
        gx = goal[i, 0] - pos[i, 0]
        gy = goal[i, 1] - pos[i, 1]
        length = np.sqrt(gx * gx + gy * gy)
        if length > 1.0:
            gx /= length
            gy /= length
        pref[i, 0] = gx + pref_offset[i, 0]
        pref[i, 1] = gy + pref_offset[i, 1]
        p[i, 0], p[i, 1] = pos[i, 0], pos[i, 1]
        v[i, 0], v[i, 1] = vel[i, 0], vel[i, 1]
        rad[i] = radii[i] + padding
        speed[i] = v_pref[i]
    _solve_world(p, v, pref, rad, speed, n, neighbor_dist, max_neighbors, time_horizon, dt, out)


# One thread per call: worlds are independent, but on a 2-core machine threads only pay when nothing else runs;
# searches and training run the policies in the same process and several searches run side by side.
@_jit
def _orca_worlds(
    pos: np.ndarray,
    vel: np.ndarray,
    pref: np.ndarray,
    radii: np.ndarray,
    max_speeds: np.ndarray,
    n_ego: int,
    neighbor_dist: np.float32,
    max_neighbors: int,
    time_horizon: np.float32,
    dt: np.float32,
    out: np.ndarray,
) -> None:
    for w in range(pos.shape[0]):
        _solve_world(
            pos[w],
            vel[w],
            pref[w],
            radii[w],
            max_speeds[w],
            n_ego,
            neighbor_dist,
            max_neighbors,
            time_horizon,
            dt,
            out[w],
        )


@_jit
def _crowd_worlds(
    pos: np.ndarray,
    vel: np.ndarray,
    goal: np.ndarray,
    radii: np.ndarray,
    v_pref: np.ndarray,
    pref_offset: np.ndarray,
    padding: np.float32,
    neighbor_dist: np.float32,
    max_neighbors: int,
    time_horizon: np.float32,
    dt: np.float32,
    out: np.ndarray,
) -> None:
    for w in range(pos.shape[0]):
        _crowd_world(
            pos[w],
            vel[w],
            goal[w],
            radii[w],
            v_pref[w],
            pref_offset[w],
            padding,
            neighbor_dist,
            max_neighbors,
            time_horizon,
            dt,
            out[w],
        )


def crowd_velocities(
    pos: np.ndarray,
    vel: np.ndarray,
    goal: np.ndarray,
    radii: np.ndarray,
    v_pref: np.ndarray,
    pref_offset: np.ndarray,
    *,
    padding: float,
    neighbor_dist: float,
    max_neighbors: int,
    time_horizon: float,
    dt: float,
) -> np.ndarray:
    """New velocities (W, n, 2) of crowds that see only each other; float64 state in, float32 solve."""
    f32 = np.float32
    out = np.empty(pos.shape, np.float32)
    _crowd_worlds(
        pos,
        vel,
        goal,
        radii,
        v_pref,
        pref_offset,
        f32(padding),
        f32(neighbor_dist),
        int(max_neighbors),
        f32(time_horizon),
        f32(dt),
        out,
    )
    return out.astype(np.float64)


def _as_batch(
    name: str, array: ArrayLike, shape_tail: tuple[int, ...], n_worlds: int | None, n: int | None
) -> np.ndarray:
    out = np.ascontiguousarray(array, dtype=np.float32)
    expect = "(B, n" + "".join(f", {d}" for d in shape_tail) + ")"
    if out.ndim != 2 + len(shape_tail) or out.shape[2:] != shape_tail:
        raise ValueError(f"{name} must have shape {expect}, got {out.shape}")
    if (n_worlds is not None and out.shape[0] != n_worlds) or (n is not None and out.shape[1] != n):
        raise ValueError(f"{name} has shape {out.shape}; every input must share B={n_worlds} and n={n}")
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return out


def orca_velocities(
    positions: ArrayLike,
    velocities: ArrayLike,
    preferred_velocities: ArrayLike,
    radii: ArrayLike,
    max_speeds: ArrayLike,
    *,
    neighbor_dist: float = 10.0,
    max_neighbors: int = 10,
    time_horizon: float = 5.0,
    dt: float = 0.25,
    n_ego: int | None = None,
) -> np.ndarray:
    """New velocities of the first ``n_ego`` agents of each world (all agents by default), shape (B, n_ego, 2).

    Agents beyond ``n_ego`` act only as neighbours: a robot steering by ORCA through a crowd needs its own
    velocity alone, and this avoids solving the humans' programs for nothing.
    """
    pos = _as_batch("positions", positions, (2,), None, None)
    n_worlds, n = pos.shape[:2]
    vel = _as_batch("velocities", velocities, (2,), n_worlds, n)
    pref = _as_batch("preferred_velocities", preferred_velocities, (2,), n_worlds, n)
    rad = _as_batch("radii", radii, (), n_worlds, n)
    speed = _as_batch("max_speeds", max_speeds, (), n_worlds, n)
    if np.any(rad < 0) or np.any(speed < 0):
        raise ValueError("radii and max_speeds must be non-negative")
    if not (neighbor_dist > 0 and time_horizon > 0 and dt > 0 and max_neighbors >= 0):
        raise ValueError("neighbor_dist, time_horizon and dt must be positive, max_neighbors non-negative")
    n_ego = n if n_ego is None else int(n_ego)
    out = np.zeros((n_worlds, n_ego, 2), np.float32)
    f32 = np.float32
    _orca_worlds(
        pos, vel, pref, rad, speed, n_ego, f32(neighbor_dist), int(max_neighbors), f32(time_horizon), f32(dt), out
    )
    return out.astype(np.float64)


def orca_step(
    positions: ArrayLike,
    velocities: ArrayLike,
    preferred_velocities: ArrayLike,
    radii: ArrayLike,
    max_speeds: ArrayLike,
    *,
    neighbor_dist: float = 10.0,
    max_neighbors: int = 10,
    time_horizon: float = 5.0,
    dt: float = 0.25,
) -> np.ndarray:
    """Every agent's new velocity (B, n, 2), as one RVO2 ``doStep`` computes it (no obstacles).

    Inputs are (B, n, 2) positions, velocities and preferred velocities, and (B, n) radii and maximum speeds;
    radii are used as given (callers add CrowdNav's padding themselves).
    """
    return orca_velocities(
        positions,
        velocities,
        preferred_velocities,
        radii,
        max_speeds,
        neighbor_dist=neighbor_dist,
        max_neighbors=max_neighbors,
        time_horizon=time_horizon,
        dt=dt,
    )
