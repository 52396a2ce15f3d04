"""The stress-controlled triclinic cell of 002_89269f1b918188b3 (Srivastava, Silbert, Grest &
Lechman): a fully periodic cell driven by an imposed pressure p_ext and shear stress tau_ext
(modularly-invariant Parrinello–Rahman, 2.10–2.16). Units: a (mean diameter), kn, t_c.

Defaults (§2.5): kn = kt, gamma_n = 0.5/t_c (rate damping), gamma_t = gamma_n/2, diameters
uniform in [0.9, 1.1] a, dt = 0.02 t_c, a dilute random start at phi = 0.05. t_c is the
binary collision time of the force law (2.17a) for two mean particles, pi (kn/m_e -
gamma_n^2/4)^(-1/2), solved together with gamma_n = 0.5/t_c (``tc_reading="collision"``, so
that 002's e_n = exp(-gamma_n t_c/2) = exp(-1/4) holds); ``tc_reading="printed"`` takes 002's
formula as printed, with 2 kn/m_e: t_c shorter by sqrt(2), e_n = 0.70 (see
:func:`contact_time` and docs/cell.md for what it changes). Density 1 (mean mass ~pi/6 in
these units). Other materials: ``size_mix`` (a discrete mix by number fraction, e.g. the
channel's {0.9: 0.3, 1.0: 0.4, 1.1: 0.3}), ``kt_ratio``, ``e_n`` (restitution instead of
gamma_n), ``form`` ("hooke" or "hertz"; with Hertz, t_c is the Hooke formula's time unit).

Start (``start``): "compacted" (the default) first compacts the dilute gas under p_ext alone
until phi settles (:meth:`ShearCell.prepare`), then switches tau_ext on; "dilute" is 002's
protocol (both on at t = 0 on the phi = 0.05 gas). Shearing the gas before it has compacted
heats it: above tau/p ~ 0.5 the dilute start ends on the overlap or dilation guard where the
compacted start reaches steady flow (docs/cell.md).

Cell mass W_g = N kn a^2 / omega_g^2. 002 prints omega_g = 2.2 sqrt(m/kn), which is a time; we
read it as omega_g = 2.2 sqrt(kn/m) (a frequency of the order of the contact frequency), the
default ``omega_g_factor = 2.2``; the stress fluctuations it gives are reported by the run.

Observables per sample (docs/columns.md, cell series; computed in the kernel's step loop,
src/sampling/cell_obs.rs) follow 002's sign conventions: the stress
is compressive-positive (2.11) and so is the strain rate, D = -sym(L), W = -skew(L) (002: a
positive eigenvalue sum is compaction); the L_ab columns stay kinematic (2.16). With these,
(4.1)–(5.4) hold as printed: mu1 > 0, mu2 = -N0/p, N1/tau = 4 mu3/mu1.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow.errors import InstabilityError, ParameterError
from granflow.simulation import run_chunked
from granflow.sizes import discrete, uniform

from ._base import SampleTables, check_keys, register, run_with_checkpoints

AX = "xyz"


def contact_time_002(kn: float, m_e: float) -> tuple[float, float]:
    """(t_c, gamma_n) with t_c = pi (2 kn/m_e - gamma_n^2/4)^(-1/2) and gamma_n = 0.5/t_c."""
    tc = np.pi / np.sqrt(2 * kn / m_e)
    for _ in range(100):
        g = 0.5 / tc
        tc = np.pi / np.sqrt(2 * kn / m_e - g * g / 4)
    return float(tc), float(0.5 / tc)


#: How the cell starts (``start``), and the compaction of a "compacted" start: stints of
#: 40 t_c until phi changes by less than COMPACT_TOL over one, at most COMPACT_MAX_STINTS.
STARTS = ("compacted", "dilute")
COMPACT_TOL = 2e-4
COMPACT_MAX_STINTS = 2000

#: How the cell reads 002's contact time (``tc_reading``).
TC_READINGS = ("printed", "collision")


def contact_time(kn: float, m_e: float, reading: str = "collision",
                 e_n: float | None = None) -> float:
    """The contact time t_c for two particles of reduced mass ``m_e``.

    002 (§2.5) prints t_c = pi (2 kn/m_e - gamma_n^2/4)^(-1/2) with gamma_n = 0.5/t_c
    (``reading="printed"``). The force law (2.17a), m_e x'' + m_e gamma_n x' + kn x = 0, makes a
    binary collision last pi (kn/m_e - gamma_n^2/4)^(-1/2) (``"collision"``), and only then is
    002's own e_n = exp(-gamma_n t_c/2) = exp(-1/4) the restitution; the printed reading gives
    t_c 1/sqrt(2) of the collision's, e_n = 0.70. Solved together with the damping:
    t_c^2 (c kn/m_e) = pi^2 + (ln e_n)^2, c = 2 (printed) or 1 (collision), where
    ln e_n = -1/4 for gamma_n = 0.5/t_c. (With ``e_n`` given, the cell's damping is the kernel's
    restitution form, derived per pair, and t_c is the time unit of that e_n.)
    """
    if reading not in TC_READINGS:
        raise ParameterError(f"invalid tc_reading = {reading!r}: allowed one of {TC_READINGS}")
    if e_n is None and reading == "printed":
        return contact_time_002(kn, m_e)[0]  # (the fixed point, as before: the same bits)
    c = 2.0 if reading == "printed" else 1.0
    log_e = -0.25 if e_n is None else float(np.log(e_n))
    return float(np.sqrt(np.pi**2 + log_e**2) / np.sqrt(c * kn / m_e))


def fabric(normals: np.ndarray) -> np.ndarray:
    """Fabric tensor A of 002 (5.1): P(n) = (1 + A : n n)/(4 pi) gives <n n> = I/3 + 2A/15,
    so A = 15/2 (<n n> - I/3), trace-free and symmetric. ``normals``: (M, 3) unit vectors."""
    n = np.asarray(normals, float)
    if len(n) == 0:
        return np.zeros((3, 3))
    return 7.5 * (n.T @ n / len(n) - np.eye(3) / 3)


@register("cell")
@dataclass
class ShearCell:
    """Stress-controlled cell scene (002 §2.2–2.5)."""

    N: int = 2000
    mu_s: float = 0.3
    p_ext: float = 1e-4
    tau_ratio: float = 0.5
    kn: float = 1.0
    phi0: float = 0.05
    d_min: float = 0.9
    d_max: float = 1.1
    size_mix: Mapping[float, float] | None = None
    density: float = 1.0
    kt_ratio: float = 1.0
    e_n: float | None = None
    form: str = "hooke"
    tc_reading: str = "collision"
    start: str = "compacted"
    omega_g_factor: float = 2.2
    dt_frac: float = 0.02
    skin: float = 0.3
    sample_every: int | None = 200
    seed: int = 0
    threads: int | None = None

    scene_name: ClassVar[str]

    def __post_init__(self) -> None:
        if not (isinstance(self.N, int) and self.N >= 50):
            raise ParameterError(f"invalid N = {self.N!r}: allowed an integer >= 50")
        if not (self.p_ext > 0):
            raise ParameterError(f"invalid p_ext = {self.p_ext}: allowed > 0")
        if not (0 <= abs(self.tau_ratio) <= 2):
            raise ParameterError(
                f"invalid tau_ratio = {self.tau_ratio}: allowed |tau_ext/p_ext| <= 2 "
                "(beyond, the method gives no steady dense flow)")
        if self.mu_s < 0:
            raise ParameterError(f"invalid mu_s = {self.mu_s}: allowed >= 0")
        if not (0 < self.phi0 <= 0.3):
            raise ParameterError(f"invalid phi0 = {self.phi0}: allowed 0 < phi0 <= 0.3")
        if not (self.sample_every is None
                or (isinstance(self.sample_every, int) and self.sample_every >= 1)):
            raise ParameterError(f"invalid sample_every = {self.sample_every!r}: allowed an "
                                 "integer >= 1, or None for no observables")
        if self.start not in STARTS:
            raise ParameterError(f"invalid start = {self.start!r}: allowed one of {STARTS}")
        if not (0 < self.dt_frac <= 0.1):
            raise ParameterError(f"invalid dt_frac = {self.dt_frac}: allowed 0 < dt_frac <= 0.1")
        self._check_material()
        if self.size_mix is not None:
            mix = {float(k): float(v) for k, v in self.size_mix.items()}
            dist = discrete(mix)
            vmean = np.pi / 6 * sum(f * k**3 for k, f in mix.items())
        else:
            dist = uniform(self.d_min, self.d_max)
            vmean = np.pi / 6 * (self.d_min + self.d_max) / 2 * (
                self.d_min**2 + self.d_max**2) / 2  # <d^3> for a uniform distribution
        d = dist.diameters_for_volume(self.N * vmean, self.seed)
        vs = float(np.sum(np.pi * d**3 / 6))
        length = (vs / self.phi0) ** (1 / 3)
        x = np.asarray(_core.insert_spheres(d, (0, 0, 0), (length,) * 3, (True,) * 3, self.seed))
        self.a = float(np.mean(d))
        m_mean = float(np.mean(self.density * np.pi * d**3 / 6))
        self.t_c = contact_time(self.kn, m_mean / 2, self.tc_reading, self.e_n)
        omega_g = self.omega_g_factor * np.sqrt(self.kn / m_mean)
        wg = len(d) * self.kn * self.a**2 / omega_g**2
        self.w_g = float(wg)  # cell mass W_g (energy balance: K_g = W_g |L|^2 / 2)
        # 002's gamma_n = 0.5/t_c (rate form), or the kernel's restitution form
        damping = {"xi_n": 0.5 / self.t_c} if self.e_n is None else {"e_n": float(self.e_n)}
        law = {"kn": self.kn, "kt": self.kt_ratio * self.kn, **damping, "xi_t_ratio": 0.5,
               "mu": self.mu_s}
        self.sim = _core.cell_sim(x, d, self.density, float(length), self.form, law,
                                  float(self.p_ext), float(self.tau_ratio * self.p_ext),
                                  float(wg), dt=self.dt_frac * self.t_c, skin=self.skin)
        if self.threads:
            self.sim.threads = int(self.threads)
        self._d = d
        self._vs = vs
        self._h0 = np.asarray(self.sim.cell()[0])
        self._tables = SampleTables()
        # observables inside the kernel's step loop (src/sampling/cell_obs.rs, docs/columns.md)
        if self.sample_every is not None:
            self.sim.add_sampler("cell_series", int(self.sample_every))
        self.phi_max = vs / length**3  # densest state seen at the run's chunk boundaries
        self.pbc = (True, True, True)
        self.wall_seconds = 0.0
        #: time at which tau_ext acts (after the compaction of a "compacted" start)
        self.shear_start_time: float | None = 0.0 if self.start == "dilute" else None

    def _check_material(self) -> None:
        """The material's parameters the scene computes with before the kernel sees them (t_c
        from kn, density and e_n; the sizes), or that it names otherwise than the kernel
        (kt_ratio, size_mix), each against its allowed range. The kernel checks the rest
        (form), and contact_time the reading."""
        if not (self.kn > 0):
            raise ParameterError(f"invalid kn = {self.kn}: allowed > 0")
        if not (0 < self.kt_ratio <= 10):
            raise ParameterError(f"invalid kt_ratio = {self.kt_ratio}: allowed 0 < kt/kn <= 10")
        if self.e_n is not None and not (0 < self.e_n <= 1):
            raise ParameterError(f"invalid e_n = {self.e_n}: allowed 0 < e_n <= 1, or None for "
                                 "002's gamma_n = 0.5/t_c")
        if not (self.density > 0):
            raise ParameterError(f"invalid density = {self.density}: allowed > 0")
        if self.size_mix is None:
            if not (0 < self.d_min <= self.d_max):
                raise ParameterError(f"invalid d_min, d_max = {self.d_min}, {self.d_max}: "
                                     "allowed 0 < d_min <= d_max")
            return
        try:
            mix = {float(k): float(v) for k, v in self.size_mix.items()}
        except (AttributeError, TypeError, ValueError) as exc:
            raise ParameterError(f"invalid size_mix = {self.size_mix!r}: allowed a mapping "
                                 "diameter -> number fraction") from exc
        if not mix or any(k <= 0 or v < 0 for k, v in mix.items()):
            raise ParameterError(f"invalid size_mix = {self.size_mix!r}: allowed diameters > 0 "
                                 "with number fractions >= 0")
        if abs(sum(mix.values()) - 1) > 1e-9:
            raise ParameterError(f"invalid size_mix = {self.size_mix!r}: the number fractions "
                                 f"sum to {sum(mix.values()):.12g}, allowed 1")

    @property
    def core(self) -> _core.Sim:
        """The kernel simulation (the same object as ``sim``)."""
        return self.sim

    def prepare(self, progress: bool | None = None) -> None:
        """For ``start="compacted"``: compact the dilute packing under p_ext alone (tau_ext = 0)
        in stints of 40 t_c until phi changes by less than ``COMPACT_TOL`` (relative) over a
        stint (at most ``COMPACT_MAX_STINTS``), then switch tau_ext on. The stints are sampled
        as any run (the series shows the compaction); ``shear_start_time`` marks the switch.
        Does nothing for ``start="dilute"``, once done, or after :meth:`restore`."""
        if self.shear_start_time is not None:
            return
        stint = max(1, round(40 / self.dt_frac))
        self.sim.set_stress(float(self.p_ext), 0.0)
        phi = self._vs / float(self.sim.volume)
        for _ in range(COMPACT_MAX_STINTS):
            self._advance(stint, progress)
            prev, phi = phi, self._vs / float(self.sim.volume)
            if abs(phi - prev) < COMPACT_TOL * phi:
                break
        self.sim.set_stress(float(self.p_ext), float(self.tau_ratio * self.p_ext))
        self.shear_start_time = float(self.sim.time)

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> ShearCell:
        check_keys("params", params, {f.name for f in fields(cls)} - {"seed", "threads"})
        return cls(**dict(params), seed=seed, threads=threads)

    def parameters(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "threads"}
        out.update(t_c=self.t_c, a=self.a)
        return out

    # -- protocol ----------------------------------------------------------------------------
    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps, sampling every ``sample_every`` steps (a "compacted" start
        compacts first, see :meth:`prepare`); ``checkpoint`` and ``checkpoint_every`` as
        :class:`granflow.scenes.Scene` says."""
        self.prepare(progress)
        run_with_checkpoints(self, steps, lambda n: self._advance(n, progress), checkpoint,
                             checkpoint_every)

    def _advance(self, steps: int, progress: bool | None) -> None:
        def after_chunk() -> None:
            self._tables.drain(self.sim)
            self.phi_max = max(self.phi_max, self._vs / float(self.sim.volume))

        try:
            run_chunked(self.sim, steps, progress, self, after_chunk=after_chunk)
        except InstabilityError as exc:
            raise InstabilityError(f"{exc}; {self.state_context()}") from exc

    def state_context(self) -> str:
        """The cell's state in words, appended to a kernel InstabilityError: phi now and its
        largest value seen, the strain rate per contact time, and, when the cell has dilated
        under shear, that runaway dilation is the underlying cause (a kernel guard other than
        the dilation guard, e.g. the overlap guard, can fire first: fast shear of a dilute cell
        means collisions at ~|L| a per t_c)."""
        obs = dict(self.sim.domain_observables())
        L = np.array([[obs[f"L_{a}{b}"] for b in AX] for a in AX])
        rate = float(np.sqrt(0.5 * np.sum((0.5 * (L + L.T)) ** 2))) * self.t_c
        phi = self._vs / float(self.sim.volume)
        msg = (f"cell state: phi = {phi:.3g} (largest seen {self.phi_max:.3g}), strain rate "
               f"|D| t_c = {rate:.3g}, tau_ext/p_ext = {self.tau_ratio:g}, "
               f"p_ext a/kn = {self.p_ext * self.a / self.kn:.3g}")
        if self.tau_ratio != 0 and phi < 0.5 * self.phi_max:
            msg += (f"; underlying cause: runaway dilation under shear (phi fell "
                    f"{self.phi_max / phi:.1f}-fold): tau_ext/p_ext = {self.tau_ratio:g} is above "
                    "what the packing sustains, the flow accelerates and dilutes")
        return msg

    def tables(self) -> dict[str, pa.Table]:
        self._tables.drain(self.sim)
        return self._tables.tables()

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        self._tables.load(tables)

    def summary(self) -> dict[str, Any]:
        from granflow.analysis import rheology as rh

        out: dict[str, Any] = {"N": self.sim.n, "t_c": self.t_c}
        t = self.tables()
        if "series" not in t or t["series"].num_rows < 20:
            return out
        try:
            res = rh.analyse_run(t["series"])
        except Exception as exc:  # too little data: say so
            out["analysis_error"] = f"{type(exc).__name__}: {exc}"
            return out
        out["state"] = getattr(res.state, "state", str(res.state))
        st = res.stats
        for k in ("mu1", "mu2", "mu3", "phi", "I", "p", "shear_rate", "beta", "N0_tau",
                  "N1_tau", "Z2", "theta_c"):
            row = st.filter(st["observable"] == k)
            if row.height:
                out[k] = float(row["mean"][0])
                out[k + "_se"] = float(row["se"][0])
        return out

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        # closed rows go to the tables first: the checkpoint carries the sampler's state
        self._tables.drain(self.sim)
        self.sim.save_checkpoint(os.fspath(path),
                                 json.dumps({"shear_start_time": self.shear_start_time}))

    def restore(self, path: str | os.PathLike[str]) -> None:
        """The kernel state of ``path``; a checkpoint is written by :meth:`run`, after the
        compaction, so the restored cell shears at tau_ext (from ``shear_start_time``, kept in
        the checkpoint's header)."""
        self.sim.load_checkpoint(os.fspath(path))
        meta = json.loads(_core.read_checkpoint_header(os.fspath(path))[1] or "{}")
        t = meta.get("shear_start_time")
        self.shear_start_time = float(t) if t is not None else float(self.sim.time)
        self.sim.set_stress(float(self.p_ext), float(self.tau_ratio * self.p_ext))


# --------------------------------------------------------------------------------------------
# energy balance of the Parrinello-Rahman cell
# --------------------------------------------------------------------------------------------
@dataclass
class EnergyBalance:
    """Energy ledger of a cell run (see :func:`energy_balance`); energies in kn a^2.

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


def energy_balance(cell: ShearCell, steps: int, every: int = 1) -> EnergyBalance:
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
    core = cell.sim
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
