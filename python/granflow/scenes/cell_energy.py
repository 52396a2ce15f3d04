"""The energy balance of the stress-controlled cell (:class:`granflow.scenes.ShearCell`): the
imposed stress's work against the change of the kinetic, elastic and cell energies and the
contact dissipation, measured independently (docs/cell.md, "Energy balance")."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .cell import AX, ShearCell


@dataclass
class EnergyBalance:
    """Energy ledger of a cell run (see :func:`cell_energy_balance`); energies in kn a^2.

    ``work`` = ``work_p`` + ``work_tau``: the imposed stress's work; ``delta_energy`` = change of
    E = kinetic (peculiar translational + rotational) + elastic (normal and tangential springs) +
    cell kinetic
    (``delta_kinetic``, ``delta_elastic``, ``delta_cell_kinetic``); ``dissipation`` = W - dE
    (inferred); ``contact_work`` = time integral of the contact power sum_i P_i (trapezoid);
    ``skew_work``, ``mtk_work``: the two small terms of the equations of motion that are neither
    (see below); ``dissipation_measured`` = -contact_work - delta_elastic (the contact
    dissipation); ``residual`` = W + skew_work - mtk_work - dE - D_measured, the closure of the
    balance (zero up to the time discretisation); ``rel_residual`` = residual / D_measured;
    ``contact_work_gross`` = time integral of sum_i |P_i| (the energy the contacts move back
    and forth); ``closure`` = residual / max(D_measured, contact_work_gross): the residual is a
    time-discretisation error of the contact power, so it scales with the gross exchange, not
    with the net dissipation (which vanishes in an arrested packing).
    """

    steps: int
    every: int
    time: float
    work_p: float
    work_tau: float
    work: float
    delta_kinetic: float
    delta_elastic: float
    delta_cell_kinetic: float
    delta_energy: float
    dissipation: float
    contact_work: float
    skew_work: float
    mtk_work: float
    dissipation_measured: float
    contact_work_gross: float
    residual: float
    rel_residual: float
    closure: float

    def as_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _trapezoid(t: np.ndarray, y: np.ndarray) -> float:
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t))) if t.size > 1 else 0.0


def cell_energy_balance(cell: ShearCell, steps: int, every: int = 1) -> EnergyBalance:
    """Run ``steps`` steps of ``cell`` (its ``series`` is not sampled meanwhile) and close the
    energy balance of the stress-controlled dynamics (002 2.10a-d as in src/domain/prcell.rs).

    With L = P_g/W_g (upper-triangular, isotropic diagonal), K the kinetic energy of the
    peculiar velocities (+ rotation), K_g = |P_g|^2/(2 W_g) and the drive of 2.10d
    dP_g/dt = V (sym sigma - sigma_ext) (projected), the equations of motion give

        d(K + K_g)/dt = sum_i P_i - V L : sigma_ext + V L : skew(sigma_c) - (2K/3N) tr L,

    where sum_i P_i is the power of all contact forces on the full relative velocities
    (streaming L r_ij included; P_i from the kernel's per-particle stats, as the channel's
    Gamma) = -dU/dt - (dissipation rate), U the elastic energy. The external work rate is
    -V L : sigma_ext = -p_ext dV/dt + tau_ext V L_xy (sigma_ext = p_ext I - tau_ext (e_x e_y +
    e_y e_x), compressive-positive): the pressure part is exactly -p_ext (V_end - V_start), the
    shear part is integrated with the trapezoid rule. skew(sigma_c) (tangential forces) enters
    because the drive uses the symmetrised stress; the 1/N term is the modularly-invariant
    friction term of 2.10b without its counterpart in 2.10d. Both are reported.

    ``every``: sampling interval in steps (1: every step; the contact power oscillates at the
    contact frequency, so the trapezoid needs a few samples per t_c). U is the kernel's elastic
    energy, normal and tangential springs.
    """
    cell.prepare()
    core = cell.core
    n = core.n
    every = max(1, int(every))
    rows: list[tuple[float, ...]] = []

    def sample() -> None:
        ke_t, ke_r, el = core.energies()
        obs = dict(core.domain_observables())
        L = np.array([[obs[f"L_{a}{b}"] for b in AX] for a in AX])
        sc = np.array([[obs[f"sigma_c_{a}{b}"] for b in AX] for a in AX])
        V = float(core.volume)
        _, pw = core.particle_stats()
        # W_g from the cell's construction (cell kinetic energy W_g |L|^2 / 2)
        kg = 0.5 * cell.w_g * float(np.sum(L * L))
        rows.append((core.time, ke_t + ke_r, el, kg, V, cell.tau_ratio * cell.p_ext * V * L[0, 1],
                     float(np.sum(pw)), V * float(np.sum(L * 0.5 * (sc - sc.T))),
                     2.0 * ke_t * float(np.trace(L)) / (3.0 * n), float(np.sum(np.abs(pw)))))

    core.request_stats()
    core.run(1)  # a step with stats: the ledger starts at a state whose contact power is known
    sample()
    done = 0
    while done < steps:
        c = min(every, steps - done)
        if c > 1:
            core.run(c - 1)
        core.request_stats()
        core.run(1)
        done += c
        sample()
    a = np.asarray(rows)
    t = a[:, 0]
    work_p = -cell.p_ext * (a[-1, 4] - a[0, 4])
    work_tau = _trapezoid(t, a[:, 5])
    contact = _trapezoid(t, a[:, 6])
    skew = _trapezoid(t, a[:, 7])
    mtk = _trapezoid(t, a[:, 8])
    gross = _trapezoid(t, a[:, 9])
    dk, de, dkg = a[-1, 1] - a[0, 1], a[-1, 2] - a[0, 2], a[-1, 3] - a[0, 3]
    work = work_p + work_tau
    d_e = dk + de + dkg
    # contact dissipation: work of the contact forces not stored as elastic energy
    dis_meas = -contact - de
    res = work + skew - mtk - d_e - dis_meas
    return EnergyBalance(
        steps=int(steps), every=every, time=float(t[-1] - t[0]), work_p=float(work_p),
        work_tau=work_tau, work=float(work), delta_kinetic=float(dk), delta_elastic=float(de),
        delta_cell_kinetic=float(dkg), delta_energy=float(d_e), dissipation=float(work - d_e),
        contact_work=contact, skew_work=skew, mtk_work=mtk, dissipation_measured=float(dis_meas),
        contact_work_gross=gross, residual=float(res),
        rel_residual=float(res / dis_meas) if dis_meas else float("nan"),
        closure=float(res / max(dis_meas, gross, 1e-300)),
    )
