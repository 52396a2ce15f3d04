"""Periodic copies of a state: every size of a benchmark made in seconds from one small state.

A state here is a dict with ``x``, ``v``, ``omega`` (N x 3), ``d`` (N) and ``hi`` (the box's
upper corner, its lower corner at the origin), and optionally ``walls`` (flat walls normal to x
as (position, sign) pairs, at the box's faces). Along a periodic axis the tiled state is exactly
periodic, so its local structure, contacts and neighbours per particle are the small state's.
Imports numpy alone (so it also runs where granflow's analysis dependencies are absent).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def tile(state: dict[str, Any], counts: tuple[int, int, int]) -> dict[str, Any]:
    """``state`` repeated ``counts`` = (nx, ny, nz) times along x, y, z: copy-major order, the
    copies nested x outermost, z innermost (the order the step-bench states were written in).
    Returns a new dict with the other keys of ``state`` kept, ``hi`` scaled and ``copies``; a
    wall at the upper x face moves to the new one (tiling along x removes the inner walls)."""
    nx, ny, nz = (int(c) for c in counts)
    if min(nx, ny, nz) < 1:
        raise ValueError(f"invalid counts = {counts}: allowed three integers >= 1")
    length = np.asarray(state["hi"], float)
    shift = np.array([[i * length[0], j * length[1], k * length[2]]
                      for i in range(nx) for j in range(ny) for k in range(nz)])
    rep = len(shift)
    walls = [(float(p), float(s)) if not math.isclose(float(p), length[0]) else
             (float(length[0] * nx), float(s)) for p, s in state.get("walls", [])]
    return {
        **state, "x": (np.asarray(state["x"])[None, :, :] + shift[:, None, :]).reshape(-1, 3),
        "v": np.tile(state["v"], (rep, 1)), "omega": np.tile(state["omega"], (rep, 1)),
        "d": np.tile(state["d"], rep), "hi": length * np.array([nx, ny, nz]),
        "copies": [nx, ny, nz], **({"walls": walls} if "walls" in state else {}),
    }  # fmt: skip


def pair_counts(n_target: float, n0: int) -> tuple[int, int]:
    """Two copy counts (a, b), a <= b, with a*b within 5 % of n_target/n0 (or the closest),
    as equal as possible."""
    c = max(1, round(n_target / n0))
    cand = [(a, max(1, round(c / a))) for a in range(1, int(math.sqrt(c)) + 1)]
    close = [t for t in cand if abs(t[0] * t[1] - c) <= 0.05 * c]
    if not close:
        close = [min(cand, key=lambda t: abs(t[0] * t[1] - c))]
    return max(close, key=lambda t: t[0])
