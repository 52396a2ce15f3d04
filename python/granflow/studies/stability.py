"""Stability suite: a registry of small runs at the edges of the parameter space, each
recorded as one row of a table.

    python -m granflow.studies.stability [--fast | --all] [--case NAME ...] [--out DIR]

runs the selected cases (default ``--fast``: the CI cases, seconds each; ``--all`` adds the long
ones meant for benchmarks/), prints the table and writes ``DIR/stability.parquet``. The exit
status is 1 if any case failed.

Columns
-------
case, group, kind ('fast' | 'long'), expect, status, passed, finished, error, max_overlap,
work, delta_energy, dissipation, energy_balance, energy_residual, energy_ok, wall_time,
nan_free, measured, n, steps, sim_time.

* ``finished``: the run completed; ``error``: the exception (type and message) otherwise.
* ``status``: 'ok', 'refused (expected)', 'scene not available' (the scene's module, or its
  part of the kernel, is not in this build; such cases have ``passed = null``: they are not
  counted as passing), or 'FAILED: <reason>'.
* ``max_overlap``: largest ``diagnostics()['max_overlap']`` (overlap / pair mean diameter) over
  the samples.
* Energy balance over the run, ``E = kinetic (translational + rotational) + elastic``:
  ``work`` W is the work of the source (gravity: the power ``M g . v_cm`` integrated with the
  trapezoid rule at the sample points; closed systems: 0), ``delta_energy`` = E_end - E_start,
  ``dissipation`` D = W - delta_energy (inferred), ``energy_balance`` = D / max(E_start, E_end,
  |W|), and ``energy_ok`` is False when ``energy_balance < -tol`` (energy created beyond the
  case's tolerance: an energy-balance violation). Null when the case has no source-work model.
* The cell (002) reports its own ledger (:func:`granflow.scenes.cell_energy_balance`, sampled every
  step over the last ``CELL_LEDGER_TC`` contact times of the run): ``work`` is the imposed
  stress's work -p_ext dV + tau_ext V L_xy dt, E includes the cell's kinetic energy,
  ``energy_balance`` = D / max(|W|, |D|, gross contact work) (the cell stores little energy;
  in an arrested cell all are noise of the size of the gross contact work's discretisation
  error) must be >= -``closure_tol``, and
  ``energy_residual`` = (W - dE - D_measured)/max(D_measured, gross contact work), with
  D_measured the contact dissipation from the kernel's per-contact power, must be within
  ``closure_tol`` (2e-3 = 0.1 dt/t_c at the cell's dt = 0.02 t_c: the closure error is first
  order in dt, measured 2.5e-4 in steady shear and 1.7e-3 in the violent compaction from the
  dilute start at this dt; docs/cell.md; ``measured`` also gives the residual over D alone).
* ``nan_free``: every sampled number, the final positions and velocities, and every float
  column of the scene's tables are finite.
* ``measured``: what the case measures (e.g. ``e_n=0.81964`` for a collision, the flow state
  of a channel).

A finished case passes when it is NaN-free, ``max_overlap < 0.25``, ``energy_ok`` is not False
and its expectation holds ('finish'; 'accelerating'; 'arrested_or_refused'; measured e_n
within ``e_n_tol`` of the law's). A case that expects a refusal passes when it raises the
expected granflow exception.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import polars as pl
import pyarrow as pa

from granflow.analysis.collision import collision_law, head_on_collision
from granflow.errors import ConfigurationError, InstabilityError, ParameterError
from granflow.material import MATERIAL_000, law_contact_time
from granflow.simulation import (
    Box,
    ContactLaw,
    Simulation,
    maxwell_velocities,
    random_packing,
)
from granflow.sizes import mono, solid_volume, uniform

if TYPE_CHECKING:
    from granflow.scenes import Scene

MAX_OVERLAP = 0.25

#: the small cell of the cell cases (granflow.scenes.cell.ShearCell parameters; units a, kn, t_c)
SMALL_CELL: dict[str, Any] = {"N": 200, "phi0": 0.3}
#: the cell's energy ledger covers the last this many contact times of a run (every step)
CELL_LEDGER_TC = 100.0


class SceneUnavailable(Exception):
    """The scene a case needs is not importable in this build."""


class Runaway(Exception):
    """A case's guard stopped a run that left the regime it can be run in (e.g. a cell
    dilating without bound)."""


class CaseTimeout(Exception):
    """A case ran past its wall-time budget."""


# --------------------------------------------------------------------------------------------
# what a case returns
# --------------------------------------------------------------------------------------------
@dataclass
class Trace:
    """Samples of one run (see :func:`drive`)."""

    t: list[float] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    power: list[float] = field(default_factory=list)
    max_overlap: list[float] = field(default_factory=list)
    vcm: list[tuple[float, float, float]] = field(default_factory=list)


@dataclass
class Outcome:
    """Result of a finished case: the samples, whether a source-work model exists, extra
    measurements and an optional state label (e.g. a channel's flow state)."""

    trace: Trace
    has_work: bool = True
    nan_free: bool = True
    measured: dict[str, Any] = field(default_factory=dict)
    state: str = ""
    n: int = 0
    steps: int = 0
    #: a ledger of the case's own (e.g. the cell's :class:`granflow.scenes.cell.EnergyBalance`
    #: as a dict); replaces the trace's source-work model when given
    balance: dict[str, float] | None = None


@dataclass(frozen=True)
class Case:
    """One stability case.

    ``run`` does the work and returns an :class:`Outcome` (or raises). ``expect`` is 'finish',
    'refused' (``refuse_with`` must be raised at set-up), 'unstable' (the run must stop with
    ``refuse_with``, e.g. the kernel's InstabilityError), 'accelerating', or
    'arrested_or_refused'.
    ``energy_tol`` bounds ``-energy_balance``; ``closure_tol`` bounds ``|energy_residual|``
    (cases with their own ledger); ``e_n`` / ``e_n_tol`` check a measured
    restitution. ``scene`` names the scene the case needs ('channel', 'cell') or None.
    ``max_wall`` is the wall-time budget in seconds (default 120 for fast, 1800 for long cases;
    checked between kernel calls, so a single very slow step is not interrupted).
    """

    name: str
    group: str
    kind: str
    run: Callable[[], Outcome]
    expect: str = "finish"
    refuse_with: tuple[type[BaseException], ...] = ()
    energy_tol: float = 1e-3
    closure_tol: float = 2e-3
    e_n: float | None = None
    e_n_tol: float = 1e-2
    scene: str | None = None
    description: str = ""
    max_wall: float | None = None


CASES: dict[str, Case] = {}


def register(case: Case) -> Case:
    """Add a case to the registry (names are unique)."""
    if case.name in CASES:
        raise ParameterError(f"invalid case name {case.name!r}: already registered")
    if case.kind not in ("fast", "long"):
        raise ParameterError(f"invalid kind = {case.kind!r}: allowed 'fast' or 'long'")
    CASES[case.name] = case
    return case


# --------------------------------------------------------------------------------------------
# driving a simulation or scene
# --------------------------------------------------------------------------------------------
def _energy(core: Any) -> float:
    e = core.energies()
    if isinstance(e, Mapping):
        return float(sum(e.values()))
    return float(sum(e))


def _gravity(obj: Any) -> np.ndarray | None:
    g = getattr(obj, "gravity", None)  # a Simulation's, or a scene's (the channel's)
    return None if g is None else np.asarray(g, dtype=float)


def _sample(core: Any, trace: Trace, g: np.ndarray | None, m: np.ndarray) -> None:
    v = np.asarray(core.velocities())
    p = (m[:, None] * v).sum(axis=0)
    trace.t.append(float(core.time))
    trace.energy.append(_energy(core))
    trace.power.append(float(g @ p) if g is not None else 0.0)
    trace.max_overlap.append(float(core.diagnostics()["max_overlap"]))
    trace.vcm.append(tuple((p / m.sum()).tolist()))


def _tables_finite(obj: Any) -> bool:
    if not hasattr(obj, "tables"):
        return True
    for tab in obj.tables().values():
        for name in tab.column_names:
            col = tab[name]
            if pa.types.is_floating(col.type):
                a = col.to_numpy(zero_copy_only=False)
                if not np.isfinite(a.astype(float)).all():
                    return False
    return True


def drive(
    obj: Any,
    steps: int,
    n_samples: int = 40,
    guard: Callable[[], str | None] | None = None,
) -> tuple[Trace, bool]:
    """Run a :class:`granflow.Simulation` or a scene for ``steps`` steps in ``n_samples``
    chunks, sampling time, energy, source power, max overlap and centre-of-mass velocity before
    the first and after every chunk. ``guard()`` is called after every chunk; a message from it
    stops the run with :class:`Runaway`. Returns the trace and whether everything is finite."""
    core = obj.core
    m = np.asarray(core.masses(), dtype=float)
    g = _gravity(obj)
    tr = Trace()
    _sample(core, tr, g, m)
    n_samples = max(1, min(int(n_samples), int(steps)))
    done = 0
    for k in range(n_samples):
        c = (int(steps) * (k + 1)) // n_samples - done
        if c > 0:
            obj.run(c, progress=False)
            done += c
        _sample(core, tr, g, m)
        msg = guard() if guard is not None else None
        if msg:
            raise Runaway(f"{msg} at t = {core.time:.4g} (step {core.step})")
    finite = bool(
        np.isfinite(core.positions()).all()
        and np.isfinite(core.velocities()).all()
        and all(np.isfinite(np.asarray(a, dtype=float)).all()
                for a in (tr.t, tr.energy, tr.power, tr.max_overlap, tr.vcm))
        and _tables_finite(obj)
    )
    return tr, finite


def energy_balance(trace: Trace) -> dict[str, float]:
    """Source work (trapezoid rule on the sampled power), change of E, inferred dissipation
    D = W - dE and the relative balance D / max(E_start, E_end, |W|)."""
    t = np.asarray(trace.t)
    pw = np.asarray(trace.power)
    w = float(np.sum(0.5 * (pw[1:] + pw[:-1]) * np.diff(t))) if t.size > 1 else 0.0
    e0, e1 = trace.energy[0], trace.energy[-1]
    de = e1 - e0
    dis = w - de
    scale = max(abs(e0), abs(e1), abs(w), 1e-300)
    return {"work": w, "delta_energy": de, "dissipation": dis, "energy_balance": dis / scale}


# --------------------------------------------------------------------------------------------
# kernel cases
# --------------------------------------------------------------------------------------------
def _collision(law: ContactLaw, d: tuple[float, float] = (1.0, 1.0)) -> Outcome:
    t_c = law_contact_time(law, np.asarray(d, float), 1.0)
    c = head_on_collision(law, t_c / 50, phase=0.37, d=d, t_c=t_c)
    tr = Trace(t=[0.0, c.steps * c.dt], energy=[c.energy_before, c.energy_after],
               power=[0.0, 0.0], max_overlap=[0.0, c.max_overlap],
               vcm=[(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)])
    return Outcome(tr, nan_free=c.finite, measured={"e_n": c.e_n}, n=2, steps=c.steps)


def _gas(
    mu: float = 0.5,
    sizes: tuple[float, float] | None = (0.9, 1.1),
    L: float = 8.0,
    phi: float = 0.3,
    kn: float = 1e5,
    e_n: float = 0.82,
    steps: int = 10_000,
    seed: int = 1,
) -> Outcome:
    box = Box(length=(L, L, L))
    dist = mono(1.0) if sizes is None else uniform(*sizes)
    x, d = random_packing(dist, box, phi, seed=seed)
    v = maxwell_velocities(len(d), 1.0, seed=seed)
    sim = Simulation(x, d, box, ContactLaw(kn=kn, e_n=e_n, mu=mu), velocities=v)
    tr, fin = drive(sim, steps)
    return Outcome(tr, nan_free=fin, n=len(d), steps=steps,
                   measured={"t_c": sim.contact_time, "dt": sim.timestep})


def _overlap_pair(overlap: float) -> Outcome:
    """Two resting unit spheres of 000's material overlapping by ``overlap`` diameters,
    non-periodic, no walls."""
    box = Box(length=(20.0, 20.0, 20.0), periodic=(False,) * 3)
    x = np.array([[10.0, 10.0, 10.0], [11.0 - overlap, 10.0, 10.0]])
    sim = Simulation(x, np.ones(2), box, MATERIAL_000.law())  # 000's contact law
    tr, fin = drive(sim, 400, n_samples=20)
    v = sim.get_velocities()
    return Outcome(tr, nan_free=fin, n=2, steps=400,
                   measured={"v_sep": float(v[1, 0] - v[0, 0])})


def _collision_case(*law_args: Any, **law_kw: Any) -> Outcome:
    return _collision(collision_law(*law_args, **law_kw))


def _register_kernel_cases() -> None:
    for kn in (1e5, 1e6, 1e7, 1e8, 1e9, 1e10):
        register(Case(
            f"collision_kn_{kn:.0e}", "kn", "fast",
            partial(_collision_case, 0.82, kn), e_n=0.82,
            description=f"head-on binary collision, hooke, kn = {kn:g}, e_n = 0.82, dt = t_c/50",
        ))
    for e in (0.05, 0.2, 0.5, 0.82, 1.0):
        register(Case(
            f"collision_e_n_{e:g}", "e_n", "fast",
            partial(_collision_case, e, 1e6), e_n=e,
            description=f"head-on binary collision, hooke, kn = 1e6, e_n = {e:g}",
        ))
    register(Case(
        "collision_e_n_hertz_0.05", "e_n", "fast",
        lambda: _collision(collision_law(0.05, 1e6, "hertz")), e_n=0.05,
        description="head-on binary collision, hertz, e_n = 0.05",
    ))
    register(Case(
        "collision_e_n_0", "e_n", "fast", lambda: _collision(collision_law(0.0, 1e6)),
        expect="refused", refuse_with=(ParameterError,),
        description="e_n = 0 (infinite damping): refused with ParameterError",
    ))
    register(Case(
        "collision_overdamped_xi_n", "e_n", "fast",
        lambda: _collision(collision_law(None, 1e6, xi_n=1e5)),
        expect="refused", refuse_with=(ParameterError,),
        description="over-damped rate xi_n = 1e5 > 2 sqrt(kn/m_eff): refused (no contact time)",
    ))
    for mu in (0.0, 0.001, 10.0):
        register(Case(
            f"gas_mu_{mu:g}", "mu", "fast", partial(_gas, mu=mu),
            description=f"periodic gas phi = 0.3, kn = 1e5, e_n = 0.82, mu = {mu:g}",
        ))
    for label, sz in (("mono", None), ("0.9-1.1", (0.9, 1.1)), ("ratio_3", (0.5, 1.5))):
        register(Case(
            f"gas_poly_{label}", "polydispersity", "fast", partial(_gas, sizes=sz),
            description=f"periodic gas phi = 0.3, mu = 0.5, diameters {sz or 'all 1'}",
        ))
    register(Case(
        "overlap_0.4", "overlap", "fast", lambda: _overlap_pair(0.4),
        expect="refused", refuse_with=(ConfigurationError,),
        description="initial overlap 0.4 d (above the 0.25 d limit): refused",
    ))
    register(Case(
        "overlap_0.2", "overlap", "fast", lambda: _overlap_pair(0.2),
        description="initial overlap 0.2 d (allowed): the pair is pushed apart, energy "
                    "released and partly dissipated",
    ))


# --------------------------------------------------------------------------------------------
# scene cases (channel 000, cell 002)
# --------------------------------------------------------------------------------------------
def _scene(name: str) -> type[Scene]:
    from granflow.scenes import get_scene

    try:
        return get_scene(name)
    except ModuleNotFoundError as exc:
        raise SceneUnavailable(f"scene {name!r} not available: {exc}") from exc


# the cases were recorded with the soft pour (it packs phi_bar = 0.58 at W = 10, H = 10, B = 4)
SMALL_CHANNEL: dict[str, Any] = {"W": 10.0, "H": 10.0, "B": 4.0, "preparation": "pour"}


def _channel(params: Mapping[str, Any], sim_time: float, n_samples: int = 50) -> Outcome:
    from granflow.analysis.channel_profiles import flow_state

    cls = _scene("channel")
    ch = cls.from_spec({**SMALL_CHANNEL, **params}, seed=0)
    ch.prepare()  # fill and release
    core = ch.core
    steps = max(1, round(sim_time / core.dt))
    tr, fin = drive(ch, steps, n_samples)
    vy = np.array([v[1] for v in tr.vcm])
    fs = flow_state({"t": np.asarray(tr.t), "vcm_y": vy})
    return Outcome(tr, nan_free=fin, state=fs.state, n=int(core.n), steps=steps,
                   measured={"flow_state": fs.state, "vcm_y_end": float(vy[-1]),
                             "accel": float(fs.slope)})


def _cell(p: float, tau_over_p: float, time_tc: float = 2000.0,
          ledger_tc: float = CELL_LEDGER_TC) -> Outcome:
    """The stress-controlled cell (002) at ``p_ext`` = p (units kn/a) and tau_ext/p_ext, run
    for ``time_tc`` contact times after its compaction under p_ext (records mu1, phi, I over
    the second half of its series, compaction included), then ``ledger_tc`` more with the
    energy ledger (granflow.scenes.cell_energy_balance)."""
    from granflow.scenes import ShearCell, cell_energy_balance

    cell = ShearCell.from_spec({**SMALL_CELL, "p_ext": p, "tau_ratio": tau_over_p}, seed=0)
    cell.prepare()
    core = cell.core
    t_c = float(cell.t_c)
    steps = max(1, round(time_tc * t_c / core.dt))
    vs = solid_volume(core.diameters())

    def dilating() -> str | None:
        vol = core.volume() if callable(core.volume) else core.volume
        phi = vs / float(vol)
        return f"the cell dilates without bound (phi = {phi:.2e})" if phi < 0.01 else None

    tr, fin = drive(cell, steps, n_samples=200, guard=dilating)
    meas: dict[str, Any] = {}
    tabs = cell.tables()
    if "series" in tabs:
        s = tabs["series"]
        for c in ("mu1", "phi", "I"):
            if c in s.column_names and s.num_rows:
                meas[c] = float(np.mean(s[c].to_numpy()[s.num_rows // 2:]))
    ledger_steps = max(1, round(ledger_tc * t_c / core.dt))
    eb = cell_energy_balance(cell, ledger_steps, every=1).as_dict()
    meas.update(W=eb["work"], D_measured=eb["dissipation_measured"],
                gross=eb["contact_work_gross"], residual_over_D=eb["rel_residual"])
    fin = fin and all(np.isfinite(v) for v in eb.values())
    return Outcome(tr, nan_free=fin, n=int(core.n), steps=steps + ledger_steps + 1,
                   measured=meas, balance=eb)


def _register_scene_cases() -> None:
    for kn in (1e5, 1e6, 1e7, 1e8):
        # the channel's dt: its material's rule (~t_c/11 at every kn)
        dt = MATERIAL_000.with_(kn=kn).dt()
        assert dt is not None
        register(Case(
            f"channel_kn_{kn:.0e}", "kn", "long",
            partial(_channel, {"kn": kn, "phi_bar": 0.58}, 20.0),
            energy_tol=2e-2, scene="channel",
            description=f"channel W=10, H=10, B=4, phi_bar = 0.58 (flows at kn = 1e6), "
                        f"kn = {kn:g}, dt = {dt:.2e}, t = 20 sqrt(d/g)",
        ))
    register(Case(
        "channel_jammed_0.66", "channel", "fast",
        lambda: _channel({"phi_bar": 0.66}, 5.0), expect="arrested_or_refused",
        refuse_with=(ParameterError,), energy_tol=2e-2, scene="channel",
        description="channel packed above random close packing (phi_bar = 0.66)",
    ))
    register(Case(
        "channel_rcp_0.64", "channel", "long",
        lambda: _channel({"phi_bar": 0.64}, 10.0), expect="arrested_or_refused",
        refuse_with=(ParameterError,), energy_tol=2e-2, scene="channel",
        description="channel at random close packing (phi_bar = 0.64): arrests",
    ))
    register(Case(
        "channel_free_fall_0.05", "channel", "fast",
        lambda: _channel({"phi_bar": 0.05}, 3.0), expect="accelerating", energy_tol=2e-2,
        scene="channel",
        description="channel so loose (phi_bar = 0.05) that it free-falls: accelerates",
    ))
    for p in (1e-6, 1e-3):
        for r in (0.0, 1.2):
            # above yield (tau/p = 1.2 > mu1 at any I the cell sustains) the cell shears and
            # dilates without bound: the kernel's dilation guard (src/domain/prcell.rs) must stop it
            above = r > 1.0
            register(Case(
                f"cell_p_{p:.0e}_tau_{r:g}", "cell", "long",
                partial(_cell, p, r, 2000.0 if p >= 1e-3 else 20000.0), scene="cell",
                expect="unstable" if above else "finish",
                refuse_with=(InstabilityError,) if above else (),
                description=f"stress-controlled cell N = 200, p_ext a/kn = {p:g}, "
                            f"tau_ext/p_ext = {r:g}, {2000 if p >= 1e-3 else 20000} t_c from a "
                            "random start at phi0 = 0.3"
                            + (": stops with InstabilityError (dilation)" if above else ""),
            ))
    register(Case(
        "cell_energy_balance", "cell", "fast", lambda: _cell(1e-3, 0.5, 400.0), scene="cell",
        description="stress-controlled cell N = 200, p_ext a/kn = 1e-3, tau_ext/p_ext = 0.5, "
                    f"400 t_c, then the energy ledger over {CELL_LEDGER_TC:g} t_c: the "
                    "imposed stress's work = dissipation + dE within closure_tol",
    ))


_register_kernel_cases()
_register_scene_cases()


# --------------------------------------------------------------------------------------------
# running
# --------------------------------------------------------------------------------------------
def _fmt_measured(meas: Mapping[str, Any]) -> str:
    parts = []
    for k, v in meas.items():
        parts.append(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}")
    return ", ".join(parts)


@contextlib.contextmanager
def _budget(seconds: float) -> Iterator[None]:
    """Raise :class:`CaseTimeout` in the main thread after ``seconds`` (SIGALRM; no-op where
    unavailable). The handler runs between kernel calls (each at most ~0.25 s of work)."""
    main = threading.current_thread() is threading.main_thread()
    if not hasattr(signal, "setitimer") or not main:
        yield
        return

    def handler(signum: int, frame: Any) -> None:  # noqa: ARG001
        raise CaseTimeout(f"wall-time budget of {seconds:g} s exceeded")

    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


def run_case(case: Case) -> dict[str, Any]:
    """Run one case and return its table row (see the module docstring)."""
    row: dict[str, Any] = {
        "case": case.name, "group": case.group, "kind": case.kind, "expect": case.expect,
        "status": "", "passed": None, "finished": False, "error": "",
        "max_overlap": None, "work": None, "delta_energy": None, "dissipation": None,
        "energy_balance": None, "energy_residual": None, "energy_ok": None, "wall_time": 0.0,
        "nan_free": None,
        "measured": "", "n": None, "steps": None, "sim_time": None,
    }
    t0 = time.perf_counter()
    budget = case.max_wall or (120.0 if case.kind == "fast" else 1800.0)
    try:
        try:
            with _budget(budget):
                out = case.run()
        except AttributeError as exc:
            if case.scene is not None and "granflow._core" in str(exc):
                raise SceneUnavailable(f"kernel not rebuilt with the {case.scene}: {exc}") from exc
            raise
    except SceneUnavailable as exc:
        row.update(status="scene not available", error=str(exc))
        return row
    except Exception as exc:  # recorded, never raised: the suite reports every case
        row["wall_time"] = time.perf_counter() - t0
        msg = f"{type(exc).__name__}: {exc}"
        row["error"] = msg
        if case.refuse_with and isinstance(exc, case.refuse_with):
            row.update(status="stopped (expected)" if case.expect == "unstable"
                       else "refused (expected)", passed=True)
        elif isinstance(exc, (Runaway, CaseTimeout)):
            row.update(status=f"FAILED: {type(exc).__name__.lower()}", passed=False)
        else:
            row.update(status=f"FAILED: {type(exc).__name__}", passed=False)
        return row
    row["wall_time"] = time.perf_counter() - t0
    tr = out.trace
    row.update(finished=True, nan_free=bool(out.nan_free), n=out.n, steps=out.steps,
               sim_time=float(tr.t[-1] - tr.t[0]) if tr.t else 0.0,
               max_overlap=float(max(tr.max_overlap)) if tr.max_overlap else 0.0,
               measured=_fmt_measured(out.measured))
    if out.balance is not None:
        b = out.balance
        # the same scale as the closure: in an arrested packing W, dE and D are all noise of
        # the size of the discretisation error of the (gross) contact work
        scale = max(abs(b["work"]), abs(b["dissipation"]), b["contact_work_gross"], 1e-300)
        row.update(work=b["work"], delta_energy=b["delta_energy"],
                   dissipation=b["dissipation"], energy_balance=b["dissipation"] / scale,
                   energy_residual=b["closure"])
        row["energy_ok"] = bool(row["energy_balance"] >= -case.closure_tol
                                and abs(b["closure"]) <= case.closure_tol)
    elif out.has_work and len(tr.t) >= 2:
        eb = energy_balance(tr)
        row.update(eb)
        row["energy_ok"] = bool(eb["energy_balance"] >= -case.energy_tol)
    problems: list[str] = []
    if not out.nan_free:
        problems.append("non-finite values")
    if row["max_overlap"] >= MAX_OVERLAP:
        problems.append(f"max_overlap {row['max_overlap']:.3g} >= {MAX_OVERLAP}")
    if row["energy_ok"] is False:
        if row["energy_residual"] is not None and abs(row["energy_residual"]) > case.closure_tol:
            problems.append(f"energy balance does not close (residual "
                            f"{row['energy_residual']:.3g} of max(dissipation, gross contact "
                            "work))")
        else:
            problems.append(f"energy created (balance {row['energy_balance']:.3g})")
    if case.expect in ("refused", "unstable"):
        problems.append(f"expected {'refusal' if case.expect == 'refused' else 'a stop'} "
                        f"({', '.join(e.__name__ for e in case.refuse_with)})")
    elif case.expect == "accelerating" and out.state != "accelerating":
        problems.append(f"expected accelerating, got {out.state or 'no state'}")
    elif case.expect == "arrested_or_refused" and out.state != "arrested":
        problems.append(f"expected arrest or refusal, got {out.state or 'no state'}")
    if case.e_n is not None and "e_n" in out.measured:
        err = abs(out.measured["e_n"] - case.e_n)
        if not err <= case.e_n_tol:
            problems.append(f"e_n off by {err:.3g} (> {case.e_n_tol:g})")
    row["passed"] = not problems
    row["status"] = "ok" if not problems else "FAILED: " + "; ".join(problems)
    return row


SCHEMA = {
    "case": pl.Utf8, "group": pl.Utf8, "kind": pl.Utf8, "expect": pl.Utf8, "status": pl.Utf8,
    "passed": pl.Boolean, "finished": pl.Boolean, "error": pl.Utf8, "max_overlap": pl.Float64,
    "work": pl.Float64, "delta_energy": pl.Float64, "dissipation": pl.Float64,
    "energy_balance": pl.Float64, "energy_residual": pl.Float64, "energy_ok": pl.Boolean,
    "wall_time": pl.Float64,
    "nan_free": pl.Boolean, "measured": pl.Utf8, "n": pl.Int64, "steps": pl.Int64,
    "sim_time": pl.Float64,
}


def select(which: str = "fast", names: Sequence[str] | None = None) -> list[Case]:
    """Cases by kind ('fast', 'long' or 'all') or by name."""
    if names:
        unknown = [n for n in names if n not in CASES]
        if unknown:
            raise ParameterError(f"invalid case {unknown[0]!r}: allowed one of {sorted(CASES)}")
        return [CASES[n] for n in names]
    if which not in ("fast", "long", "all"):
        raise ParameterError(f"invalid selection {which!r}: allowed 'fast', 'long' or 'all'")
    return [c for c in CASES.values() if which == "all" or c.kind == which]


def run_suite(
    which: str = "fast",
    names: Sequence[str] | None = None,
    out: str | os.PathLike[str] | None = None,
    verbose: bool = False,
) -> pl.DataFrame:
    """Run the selected cases; write ``out/stability.parquet`` when ``out`` is given."""
    rows = []
    for case in select(which, names):
        r = run_case(case)
        if verbose:
            print(f"{case.name:<28} {r['status']:<22} {r['wall_time']:8.2f} s  {r['measured']}",
                  flush=True)
        rows.append(r)
    table = pl.DataFrame(rows, schema=SCHEMA)
    if out is not None:
        from granflow.io import write_parquet

        write_parquet(table.to_arrow(), Path(out) / "stability.parquet",
                      params={"suite": "stability", "selection": which,
                              "cases": [c.name for c in select(which, names)]})
    return table


def format_table(table: pl.DataFrame) -> str:
    """Plain-text summary: one line per case."""
    def f(v: Any, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    lines = [f"{'case':<26} {'kind':<4} {'status':<20} {'max_ov':>8} {'D/E':>9} "
             f"{'wall[s]':>7}  measured / error"]
    for r in table.iter_rows(named=True):
        st = r["status"] if len(r["status"]) <= 20 else r["status"][:17] + "..."
        lines.append(
            f"{r['case']:<26} {r['kind']:<4} {st:<20} {f(r['max_overlap'], '8.2e')} "
            f"{f(r['energy_balance'], '9.2e')} {r['wall_time']:7.2f}  "
            f"{r['measured'] or r['error']}"
        )
        if r["status"].startswith("FAILED") and len(r["status"]) > 20:
            lines.append(f"{'':<26} {r['status']}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: see the module docstring."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m granflow.studies.stability",
                                 description="granflow stability suite")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--fast", action="store_const", dest="which", const="fast",
                   help="the CI cases (default)")
    g.add_argument("--long", action="store_const", dest="which", const="long",
                   help="only the long cases")
    g.add_argument("--all", action="store_const", dest="which", const="all",
                   help="every case")
    ap.add_argument("--case", action="append", default=None, help="run this case (repeatable)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--out", default=None, help="directory for stability.parquet")
    a = ap.parse_args(argv)
    which = a.which or "fast"
    if a.list:
        for c in select("all"):
            print(f"{c.name:<28} {c.kind:<4} {c.expect:<20} {c.description}")
        return 0
    table = run_suite(which, a.case, a.out, verbose=True)
    print()
    print(format_table(table))
    failed = table.filter(pl.col("passed") == False)  # noqa: E712 - polars expression
    na = table.filter(pl.col("passed").is_null()).height
    print(f"\n{table.height} cases: {table.filter(pl.col('passed')).height} passed, "
          f"{failed.height} failed, {na} not available")
    return 1 if failed.height else 0


if __name__ == "__main__":
    raise SystemExit(main())
