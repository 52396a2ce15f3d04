"""The granflow simulation of a benchmark state: one way for every benchmark to build it.

A state is a dict with ``x``, ``v``, ``omega`` (N x 3), ``d`` (N), ``hi`` (the box's upper
corner), and optionally ``lo`` (its lower corner, the origin if absent), ``periodic`` (three
flags, all periodic if absent) and ``walls`` (flat walls normal to x as (position, sign) pairs,
none if absent) -- what ``compare_lammps.channel_state`` and ``benchmarks/tiling.py`` give.
Imports numpy and granflow's kernel alone (no polars), so it also runs on a bare machine.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def simulation(st: dict[str, Any], law: Any, *, density: float, dt: float, skin: float,
               gravity: float | None = None, threads: int = 1,
               omega: bool = True) -> Any:
    """``granflow.Simulation`` of ``st`` with the contact law ``law`` (a ``granflow.ContactLaw``)
    for pairs and walls; ``gravity`` is its magnitude along -y (None: none); ``omega=False``
    starts the particles without spin."""
    import granflow as gf

    hi = np.asarray(st["hi"], float)
    lo = np.asarray(st.get("lo", np.zeros(3)), float)
    walls = [gf.Wall(0, float(p), float(s)) for p, s in st.get("walls", [])]
    return gf.Simulation(
        st["x"], st["d"],
        gf.Box(length=tuple(hi - lo), lo=tuple(lo),
               periodic=tuple(st.get("periodic", (True, True, True)))),
        law, density=density, velocities=st["v"],
        angular_velocities=st["omega"] if omega else np.zeros_like(st["v"]),
        walls=walls, wall_law=law if walls else None,
        gravity=None if gravity is None else (0.0, -gravity, 0.0), dt=dt, skin=skin,
        threads=threads,
    )  # fmt: skip
