"""Two spheres colliding head on (:func:`head_on_collision`): the measured normal restitution
of a contact law at a time step, against the law's analytic ``e_n`` (granflow.studies.timestep
tabulates it against dt)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from granflow.errors import GranflowError, ParameterError
from granflow.material import law_contact_time
from granflow.simulation import Box, ContactLaw, Simulation


@dataclass
class Collision:
    """One head-on collision (see :func:`head_on_collision`)."""

    e_n: float
    dt: float
    t_c: float
    steps: int
    wall_time: float
    max_overlap: float
    energy_before: float
    energy_after: float
    finite: bool


def collision_law(e_n: float | None = 0.82, kn: float = 1e6, form: str = "hooke",
                  xi_n: float | None = None) -> ContactLaw:
    """Frictionless law for a head-on collision (give ``e_n`` or ``xi_n``)."""
    if xi_n is not None:
        return ContactLaw(kn=kn, e_n=None, xi_n=xi_n, mu=0.0, form=form)
    return ContactLaw(kn=kn, e_n=e_n, mu=0.0, form=form)


def head_on_collision(
    law: ContactLaw,
    dt: float | None = None,
    *,
    phase: float = 0.5,
    v0: float = 1.0,
    d: tuple[float, float] = (1.0, 1.0),
    density: float = 1.0,
    gap_tc: float = 0.5,
    max_contact_tc: float = 200.0,
    t_c: float | None = None,
) -> Collision:
    """Two spheres approaching head on at relative speed ``v0`` along x, in a non-periodic box
    without walls; run until they are out of contact and moving apart, then measure
    ``e_n = -(v1 - v2).n_after / (v1 - v2).n_before``.

    The initial gap is ``v0 dt (m + phase)`` with ``m = round(gap_tc t_c / dt)``, so the contact
    starts at the fraction ``phase`` of a step. The run advances in chunks of about ``t_c/4``
    straight on the kernel handle (no progress bar); ``wall_time`` is the time spent in them.
    ``t_c`` (default: the kernel's for the pair, material.law_contact_time) saves the probe
    simulation when already known.
    """
    if not 0.0 <= phase < 1.0:
        raise ParameterError(f"invalid phase = {phase}: allowed 0 <= phase < 1")
    if not (math.isfinite(v0) and v0 > 0):
        raise ParameterError(f"invalid v0 = {v0}: allowed > 0")
    if t_c is None:
        t_c = law_contact_time(law, np.asarray(d, float), density)
    dt = t_c / 50 if dt is None else float(dt)
    m = max(1, round(gap_tc * t_c / dt))
    gap = v0 * dt * (m + phase)
    L = 8.0 * max(d) + 2.0 * gap
    c = 0.5 * L
    x = np.array([[c - 0.5 * d[0] - 0.5 * gap, c, c], [c + 0.5 * d[1] + 0.5 * gap, c, c]])
    dd = np.asarray(d, dtype=float)
    m1, m2 = (density * np.pi * dd**3 / 6).tolist()
    v = np.array([[v0 * m2 / (m1 + m2), 0, 0], [-v0 * m1 / (m1 + m2), 0, 0]])
    sim = Simulation(x, dd, Box(length=(L, L, L), periodic=(False,) * 3), law, density=density,
                     velocities=v, dt=dt)
    core = sim.core
    e0 = sum(sim.energies().values())
    chunk = max(1, int(0.25 * t_c / dt))
    max_steps = int((gap / v0 + max_contact_tc * t_c) / dt) + 1
    max_ov = 0.0
    wall = 0.0
    steps = 0
    vrel = -v0
    while steps < max_steps:
        t0 = time.perf_counter()
        core.run(chunk)
        wall += time.perf_counter() - t0
        steps += chunk
        dg = core.diagnostics()
        max_ov = max(max_ov, float(dg["max_overlap"]))
        vv = core.velocities()
        vrel = float(vv[1, 0] - vv[0, 0])  # > 0: moving apart (particle order is stable here)
        if dg["contacts"] == 0 and vrel > 0:
            break
    else:
        raise GranflowError(
            f"collision did not end within {max_contact_tc:g} t_c (dt = {dt:.3e}, t_c = "
            f"{t_c:.3e}); relative velocity {vrel:.3e}"
        )
    e1 = sum(sim.energies().values())
    xs = core.positions()
    finite = bool(np.isfinite(xs).all() and np.isfinite(core.velocities()).all())
    return Collision(vrel / v0, dt, t_c, steps, wall, max_ov, e0, e1, finite)
