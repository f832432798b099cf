"""Compiled glue of the NMPC's period (numba ``njit``, cached): the parameter vector, the
warm start and the SQP's iterate update, each one call instead of a dozen small numpy
operations. Each computes what the numpy expressions it replaces compute (the same IEEE
operations in the same order, no fast-math; tested in ``tests/test_control_compiled.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def prepare(estimate: np.ndarray, preview: np.ndarray, lo: float, hi: float, u_prev: float,
            theta: np.ndarray, lim: tuple, p_min: float, x_scale: np.ndarray,
            prev_w: np.ndarray, warm: bool, n: int, d: int, nb: int, p_out: np.ndarray,
            w_out: np.ndarray) -> None:
    """The OCP parameters and the initial guess of one solve (``_MpcBase``'s numpy path).

    x0 = estimate[:4] with both pressures raised to p_min; p_out = [x0, the preview
    saturated to [lo, hi] (numpy's maximum, then minimum), u_prev, theta, lim]; w_out =
    ``prev_w`` shifted one interval with its first collocation block at x0 / x_scale
    (``warm``), else the cold start (zero inputs and slacks, every state at x0 / x_scale).
    """
    x0 = np.empty(4)
    for i in range(4):
        x0[i] = estimate[i]
    if x0[0] < p_min:
        x0[0] = p_min
    if x0[1] < p_min:
        x0[1] = p_min
    for i in range(4):
        p_out[i] = x0[i]
    for i in range(n + 1):
        p_out[4 + i] = np.minimum(np.maximum(preview[i], lo), hi)
    j = 5 + n
    p_out[j] = u_prev
    for i in range(3):
        p_out[j + 1 + i] = theta[i]
    for i in range(4):
        p_out[j + 4 + i] = lim[i]
    scaled = np.empty(4)
    for i in range(4):
        scaled[i] = x0[i] / x_scale[i]
    k = 4 * d
    if warm:
        for i in range(w_out.size):
            w_out[i] = prev_w[i]
        for i in range(n - 1):                       # slacks one interval forward
            w_out[nb + i] = prev_w[nb + 1 + i]
        start = nb + n
        for i in range((n - 2) * k):                 # collocation blocks likewise
            w_out[start + k + i] = prev_w[start + 2 * k + i]
        for r in range(d):                           # the first block at the measurement
            for i in range(4):
                w_out[start + 4 * r + i] = scaled[i]
    else:
        for i in range(nb + n):
            w_out[i] = 0.0
        for r in range(d * n):
            for i in range(4):
                w_out[nb + n + 4 * r + i] = scaled[i]


@njit(cache=True)
def update(w: np.ndarray, lam_g: np.ndarray, lam_x: np.ndarray, dx: np.ndarray,
           dlam_g: np.ndarray, dlam_x: np.ndarray, t: float) -> None:
    """The SQP's step of length t: w += t·dx (w += dx at t = 1) and the multipliers blended
    lam·(1 − t) + t·dlam (the QP's at t = 1)."""
    if t == 1.0:
        for i in range(lam_g.size):
            lam_g[i] = dlam_g[i]
        for i in range(lam_x.size):
            lam_x[i] = dlam_x[i]
        for i in range(w.size):
            w[i] += dx[i]
        return
    keep = 1.0 - t
    for i in range(lam_g.size):
        lam_g[i] = lam_g[i] * keep + t * dlam_g[i]
    for i in range(lam_x.size):
        lam_x[i] = lam_x[i] * keep + t * dlam_x[i]
    for i in range(w.size):
        w[i] += t * dx[i]


@njit(cache=True)
def finish(w: np.ndarray, lam_g: np.ndarray, nb: int, lb: int, plan: np.ndarray,
           write_plan: bool) -> bool:
    """Whether w and lam_g are all finite; if so and ``write_plan``, plan = w[:nb] with
    each value repeated lb times (``np.repeat``)."""
    for x in w:
        if not np.isfinite(x):
            return False
    for x in lam_g:
        if not np.isfinite(x):
            return False
    if write_plan:
        for b in range(nb):
            for i in range(lb):
                plan[b * lb + i] = w[b]
    return True
