"""The stress-controlled triclinic cell of 002_89269f1b918188b3 (Srivastava, Silbert, Grest &
Lechman): a fully periodic cell driven by an imposed pressure p_ext and shear stress tau_ext
(modularly-invariant Parrinello–Rahman, 2.10–2.16). Units: a (mean diameter), kn, t_c.

Material (§2.5, :data:`granflow.material.MATERIAL_002`): kn = kt, gamma_n = 0.5/t_c (rate
damping), gamma_t = gamma_n/2, mu = 0.3, diameters uniform in [0.9, 1.1] a, dt = 0.02 t_c;
a dilute random start at phi = 0.05. t_c is the binary collision time of the force law (2.17a)
for two mean particles, pi (kn/m_e - gamma_n^2/4)^(-1/2), solved together with gamma_n =
0.5/t_c (``tc_reading="collision"``, so that 002's e_n = exp(-gamma_n t_c/2) = exp(-1/4)
holds); ``tc_reading="printed"`` takes 002's formula as printed, with 2 kn/m_e: t_c shorter by
sqrt(2), e_n = 0.70 (see :meth:`granflow.material.Material.contact_time` and docs/cell.md for
what it changes). Density 1 (mean mass ~pi/6 in these units). Other materials: ``material=``
or the flat overrides (``sizes``, e.g. the channel's {0.9: 0.3, 1.0: 0.4, 1.1: 0.3}, ``kt_ratio``,
``e_n`` (restitution instead of gamma_n), ``form`` ("hooke" or "hertz"; with Hertz, t_c is the
Hooke formula's time unit), ...).

N sets the solid volume, not the count: the cell holds N mean particles' volume, N <pi d^3/6>,
filled with whole particles drawn from the size distribution, so ``ShearCell(N=2000)`` holds
1996 particles; ``n`` (in :meth:`ShearCell.summary` and :meth:`ShearCell.parameters`) is the
count.

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

import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow.errors import ConfigurationError, DilationError, InstabilityError, ParameterError
from granflow.material import MATERIAL_002, Material
from granflow.simulation import run_chunked
from granflow.sizes import solid_volume
from granflow.states import FlowState

from ._base import (
    SampleTables,
    SceneParameters,
    check_run_keys,
    read_checkpoint_state,
    register,
    run_with_checkpoints,
    write_checkpoint,
)

AX = "xyz"

#: How the cell starts (``start``), and the compaction of a "compacted" start: stints of
#: COMPACT_STINT_TC t_c until phi changes by less than COMPACT_TOL over one, at most
#: COMPACT_MAX_STINTS.
STARTS = ("compacted", "dilute")
COMPACT_STINT_TC = 40
COMPACT_TOL = 2e-4
COMPACT_MAX_STINTS = 2000

#: The kernel's dilation guard (src/domain/prcell.rs) starts its message so.
KERNEL_DILATION_MESSAGE = "the cell dilated"
#: A cell stopped by another guard has dilated under shear when phi fell below this fraction
#: of its largest value.
DILATED_PHI_FRACTION = 0.5
#: the largest barostat frequency times dt (ShearCell's omega_g_factor check)
OMEGA_G_DT_MAX = 1.0


def fabric(normals: np.ndarray) -> np.ndarray:
    """Fabric tensor A of 002 (5.1): P(n) = (1 + A : n n)/(4 pi) gives <n n> = I/3 + 2A/15,
    so A = 15/2 (<n n> - I/3), trace-free and symmetric. ``normals``: (M, 3) unit vectors."""
    n = np.asarray(normals, float)
    if len(n) == 0:
        return np.zeros((3, 3))
    return 7.5 * (n.T @ n / len(n) - np.eye(3) / 3)


@register("cell")
@dataclass
class ShearCell(SceneParameters):
    """Stress-controlled cell scene (002 §2.2–2.5).

    The material, its flat overrides, ``dt``, ``seed`` and ``threads`` are every scene's
    (:class:`~granflow.scenes.SceneParameters`); the cell's material is
    :data:`granflow.material.MATERIAL_002` unless ``material`` says otherwise, and its ``dt``
    None is that material's rule (002: 0.02 t_c). The kernel is built by :meth:`prepare` (or
    :meth:`restore`, :meth:`run`).

    Args:
        N: The solid volume in mean particles (N <pi d^3/6>), filled with whole particles: the
            count ``n`` differs slightly (N = 2000 gives 1996 with 002's sizes).
        p_ext: The imposed pressure (units kn/a).
        tau_ratio: The imposed shear stress over the pressure, tau_ext/p_ext.
        phi0: The volume fraction of the dilute random start.
        start: "compacted" (compact under p_ext alone first) or "dilute" (002's protocol;
            module docstring).
        omega_g_factor: The cell mass's frequency factor (module docstring).
        sample_every: Steps between two rows of the ``series`` table of observables (None:
            no observables).
    """

    N: int = 2000
    p_ext: float = 1e-4
    tau_ratio: float = 0.5
    phi0: float = 0.05
    start: str = "compacted"
    omega_g_factor: float = 2.2
    sample_every: int | None = 200

    scene_name: ClassVar[str]
    default_material: ClassVar[Material] = MATERIAL_002
    #: the runner writes the statistical-error report of a finished run
    error_report: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not (isinstance(self.N, int) and self.N >= 50):
            raise ParameterError(f"invalid N = {self.N!r}: allowed an integer >= 50 (the solid "
                                 "volume in mean particles; the count n follows from it)")
        if not (self.p_ext > 0):
            raise ParameterError(f"invalid p_ext = {self.p_ext}: allowed > 0")
        if not (0 <= abs(self.tau_ratio) <= 2):
            raise ParameterError(
                f"invalid tau_ratio = {self.tau_ratio}: allowed |tau_ext/p_ext| <= 2 "
                "(beyond, the method gives no steady dense flow)")
        if not (0 < self.phi0 <= 0.3):
            raise ParameterError(f"invalid phi0 = {self.phi0}: allowed 0 < phi0 <= 0.3")
        if not (self.sample_every is None
                or (isinstance(self.sample_every, int) and self.sample_every >= 1)):
            raise ParameterError(f"invalid sample_every = {self.sample_every!r}: allowed an "
                                 "integer >= 1, or None for no observables")
        if self.start not in STARTS:
            raise ParameterError(f"invalid start = {self.start!r}: allowed one of {STARTS}")
        mat = self._resolve_material()
        d = mat.sizes.diameters_for_volume(self.N * mat.sizes.mean_volume, self.seed)
        self._d = d
        self._vs = vs = solid_volume(d)
        self._length = float((vs / self.phi0) ** (1 / 3))
        self.a = float(np.mean(d))
        m_mean = mat.mean_mass(d)
        self.t_c = mat.contact_time("mean", d)
        dt = self.timestep
        if not (dt is not None and 0 < dt <= 0.1 * self.t_c):
            raise ParameterError(f"invalid dt = {dt!r}: allowed 0 < dt <= 0.1 t_c = "
                                 f"{0.1 * self.t_c:.4g}, or None for the material's rule")
        # The barostat is a controller of gain 1/W_g: its oscillation, at ~omega_g, must be
        # resolved by the leapfrog step (stable for omega dt < 2; OMEGA_G_DT_MAX keeps a margin
        # for the packing's stiffening, which raises the frequency)
        f_max = OMEGA_G_DT_MAX / (float(np.sqrt(mat.kn_value / m_mean)) * dt)
        if not (0 < self.omega_g_factor <= f_max):
            raise ParameterError(
                f"invalid omega_g_factor = {self.omega_g_factor!r}: allowed 0 < omega_g_factor "
                f"<= {f_max:.3g} (omega_g dt <= {OMEGA_G_DT_MAX:g} at dt = {dt:.4g}: a stiffer "
                "barostat is not resolved by the time step and cannot be stable)")
        omega_g = self.omega_g_factor * np.sqrt(mat.kn_value / m_mean)
        self.w_g = float(len(d) * mat.kn_value * self.a**2 / omega_g**2)
        self._core: _core.Sim | None = None
        self._tables = SampleTables()
        self.phi_max = vs / self._length**3  # densest state seen at the run's chunk boundaries
        self.pbc = (True, True, True)
        self.wall_seconds = 0.0
        #: time at which tau_ext acts (after the compaction of a "compacted" start)
        self.shear_start_time: float | None = None

    @property
    def n(self) -> int:
        """The particle count (N sets the solid volume; see the class docstring)."""
        return len(self._d)

    @property
    def timestep(self) -> float | None:
        """The run's dt: ``dt``, or the material's rule for these particles."""
        return self.dt if self.dt is not None else self.mat.dt(self._d)

    def _build(self) -> _core.Sim:
        """The kernel simulation of the dilute start: random insertion at phi0, p_ext and
        tau_ext on."""
        if self._core is not None:
            return self._core
        mat, d, length = self.mat, self._d, self._length
        x = np.asarray(_core.insert_spheres(d, (0, 0, 0), (length,) * 3, (True,) * 3, self.seed))
        # 002's gamma_n = gamma_n_tc/t_c (rate form), or the kernel's restitution form
        law = mat.law(d).as_dict()
        core = _core.cell_sim(x, d, mat.density, float(length), mat.form, law,
                              float(self.p_ext), float(self.tau_ratio * self.p_ext),
                              float(self.w_g), dt=self.timestep, skin=mat.skin)
        if self.threads:
            core.threads = int(self.threads)
        self._h0 = np.asarray(core.cell()[0])
        # observables inside the kernel's step loop (src/sampling/cell_obs.rs, docs/columns.md)
        if self.sample_every is not None:
            core.add_sampler("cell_series", int(self.sample_every))
        self._core = core
        return core

    @property
    def prepared(self) -> bool:
        """Whether the kernel simulation exists (after :meth:`prepare`, :meth:`run` or
        :meth:`restore`)."""
        return self._core is not None

    @property
    def core(self) -> _core.Sim:
        """The kernel simulation (after :meth:`prepare`, :meth:`run` or :meth:`restore`;
        before, a :class:`granflow.ConfigurationError`)."""
        if self._core is None:
            raise ConfigurationError(
                "cell not prepared: call prepare() (or run(), or restore()) first")
        return self._core

    def prepare(self, progress: bool | None = None) -> None:
        """Build the kernel simulation on the dilute start. For ``start="compacted"`` then
        compact it under p_ext alone (tau_ext = 0) in stints of 40 t_c until phi changes by
        less than ``COMPACT_TOL`` (relative) over a stint (at most ``COMPACT_MAX_STINTS``),
        and switch tau_ext on. The stints are sampled as any run (the series shows the
        compaction); ``shear_start_time`` marks the switch. Does nothing once done, or after
        :meth:`restore`."""
        core = self._build()
        if self.shear_start_time is not None:
            return
        if self.start == "dilute":
            self._drive(core)
            self.shear_start_time = 0.0
            return
        dt = self.timestep
        assert dt is not None
        stint = max(1, round(COMPACT_STINT_TC * self.t_c / dt))
        core.set_stress(float(self.p_ext), 0.0)
        phi = self._vs / float(core.volume)
        for _ in range(COMPACT_MAX_STINTS):
            self._advance(stint, progress)
            prev, phi = phi, self._vs / float(core.volume)
            if abs(phi - prev) < COMPACT_TOL * phi:
                break
        self._drive(core)
        self.shear_start_time = float(core.time)

    def _drive(self, core: _core.Sim) -> None:
        """Switch the driving on: p_ext and tau_ext (a subclass may drive otherwise)."""
        core.set_stress(float(self.p_ext), float(self.tau_ratio * self.p_ext))

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> ShearCell:
        """A cell from a TOML spec's ``params`` (the field names)."""
        check_run_keys(params, cls)
        return cls(**dict(params), seed=seed, threads=threads)

    def parameters(self) -> dict[str, Any]:
        """Every parameter (the material's fields flat, ``law`` as the kernel gets it), the
        run's ``dt``, ``t_c``, the mean diameter ``a`` and the particle count ``n``."""
        out = {f.name: getattr(self, f.name) for f in fields(self)
               if f.name not in ("threads", "material")}
        out.update(self.mat.parameters())
        out.update(law=self.mat.law(self._d).as_dict(), dt=self.timestep, t_c=self.t_c,
                   a=self.a, n=self.n)
        return out

    # -- protocol ----------------------------------------------------------------------------
    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps, sampling every ``sample_every`` steps (preparing first: a
        "compacted" start compacts, see :meth:`prepare`); ``checkpoint`` and
        ``checkpoint_every`` as :class:`granflow.scenes.Scene` says."""
        self.prepare(progress)
        run_with_checkpoints(self, steps, lambda n: self._advance(n, progress), checkpoint,
                             checkpoint_every)

    def _advance(self, steps: int, progress: bool | None) -> None:
        core = self.core

        def after_chunk() -> None:
            self._tables.drain(core)
            self.phi_max = max(self.phi_max, self._vs / float(core.volume))

        try:
            run_chunked(core, steps, progress, self, after_chunk=after_chunk)
        except InstabilityError as exc:
            dilated = KERNEL_DILATION_MESSAGE in str(exc) or self._dilated()
            kind = DilationError if dilated else InstabilityError
            raise kind(f"{exc}; {self.state_context()}") from exc

    def _phi(self) -> float:
        return self._vs / float(self.core.volume)

    def _dilated(self) -> bool:
        """Whether the sheared cell has dilated: phi below DILATED_PHI_FRACTION of its
        largest value."""
        return self.tau_ratio != 0 and self._phi() < DILATED_PHI_FRACTION * self.phi_max

    def state_context(self) -> str:
        """The cell's state in words, appended to a kernel InstabilityError: phi now and its
        largest value seen, the strain rate per contact time, and, when the cell has dilated
        under shear, that runaway dilation is the underlying cause (a kernel guard other than
        the dilation guard, e.g. the overlap guard, can fire first: fast shear of a dilute cell
        means collisions at ~|L| a per t_c)."""
        obs = dict(self.core.domain_observables())
        L = np.array([[obs[f"L_{a}{b}"] for b in AX] for a in AX])
        rate = float(np.sqrt(0.5 * np.sum((0.5 * (L + L.T)) ** 2))) * self.t_c
        phi = self._phi()
        kn = self.mat.kn_value
        msg = (f"cell state: phi = {phi:.3g} (largest seen {self.phi_max:.3g}), strain rate "
               f"|D| t_c = {rate:.3g}, tau_ext/p_ext = {self.tau_ratio:g}, "
               f"p_ext a/kn = {self.p_ext * self.a / kn:.3g}")
        if self._dilated():
            msg += (f"; underlying cause: runaway dilation under shear (phi fell "
                    f"{self.phi_max / phi:.1f}-fold): tau_ext/p_ext = {self.tau_ratio:g} is above "
                    "what the packing sustains, the flow accelerates and dilutes")
        return msg

    def tables(self) -> dict[str, pa.Table]:
        """The sample tables by name (``series``; docs/columns.md)."""
        if self._core is not None:
            self._tables.drain(self._core)
        return self._tables.tables()

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        """Start from tables written earlier (a resumed run)."""
        self._tables.load(tables)

    def summary(self) -> dict[str, Any]:
        """002's analysis (granflow.analysis.rheology.analyse_run) flattened to scalars:
        ``n``, ``t_c``, ``state`` (:class:`granflow.states.FlowState`) and each value with its
        ``<name>_se``."""
        from granflow.analysis import rheology as rh

        out: dict[str, Any] = {"n": self.n, "t_c": self.t_c}
        t = self.tables()
        if "series" not in t or t["series"].num_rows < 20:
            return out
        try:
            res = rh.analyse_run(t["series"])
        except Exception as exc:  # too little data: say so
            out["analysis_error"] = f"{type(exc).__name__}: {exc}"
            return out
        out["state"] = FlowState(getattr(res.state, "state", str(res.state)))
        st = res.stats
        for k in ("mu1", "mu2", "mu3", "phi", "I", "p", "shear_rate", "beta", "N0_tau",
                  "N1_tau", "Z2", "theta_c"):
            row = st.filter(st["observable"] == k)
            if row.height:
                out[k] = float(row["mean"][0])
                out[k + "_se"] = float(row["se"][0])
        return out

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        """The kernel state and the shear start (:func:`write_checkpoint`)."""
        # closed rows go to the tables first: the checkpoint carries the sampler's state
        self._tables.drain(self.core)
        write_checkpoint(self, path, {"shear_start_time": self.shear_start_time})

    def restore(self, path: str | os.PathLike[str]) -> None:
        """The kernel state of ``path``; a checkpoint is written by :meth:`run`, after the
        compaction, so the restored cell shears at tau_ext (from ``shear_start_time``, kept in
        the checkpoint's header)."""
        state = read_checkpoint_state(path, self.scene_name)
        core = self._build()
        core.load_checkpoint(os.fspath(path))
        t = state.get("shear_start_time")
        self.shear_start_time = float(t) if t is not None else float(core.time)
        self._drive(core)
