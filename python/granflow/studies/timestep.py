"""Discretisation error: timestep (work-precision) studies.

The same short scene is run at ``dt = t_c / f`` for ``f`` in ``fracs`` (default 10, 20, 50, 100,
200; ``t_c`` is the contact time of the stiffest, lightest pair of the linear law, as used by the
kernel for its default ``t_c / 50`` and its refusal above ``t_c / 10``; for the cell, 002's
``t_c`` of two mean particles, the cell's own time unit), always over the same simulated time,
and each observable's deviation from a reference is tabulated against the wall-clock time
spent:

* :func:`binary_collision_study` — two spheres colliding head on in a non-periodic box without
  walls; the measured normal restitution is compared with the analytic ``e_n`` of the law
  (000 App. A: the damping is derived from ``e_n`` per pair, so the continuous-time restitution is
  exactly ``e_n``). The dashpot force jumps at contact onset, so the error depends on where in a
  step the contact starts; every ``dt`` is therefore run at ``phases`` equally spaced onset phases
  and the phase mean (``e_n``) and worst case (``e_n_max_error``) are reported.
* :func:`scene_study` — any scene (protocol of :mod:`granflow.scenes`) or
  :class:`granflow.Simulation` built by a factory taking ``dt``; deviations are from the finest
  run.
* :func:`sheared_packing_study` — :func:`scene_study` on a sheared packing in the
  stress-controlled cell (``granflow.scenes.cell.ShearCell``): steady averages with their SEs; a
  clear :class:`granflow.GranflowError` if that scene is not available in this build.
* :func:`work_precision_plot` — |deviation| against wall time, one line per observable.

Every study returns a polars DataFrame with columns ``dt_label, frac, dt, steps, wall_time,
observable, value, se, reference, deviation, rel_deviation`` (``deviation = value -
reference``; ``se`` the standard error of a time-averaged observable, null otherwise).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import polars as pl

from granflow.analysis.collision import collision_law, head_on_collision
from granflow.errors import GranflowError, ParameterError
from granflow.material import DtRule, law_contact_time
from granflow.simulation import Box, ContactLaw, Simulation

if TYPE_CHECKING:
    from granflow.scenes import Scene

DEFAULT_FRACS: tuple[int, ...] = (10, 20, 50, 100, 200)
#: the cell's (:func:`sheared_packing_study`): its t_c is the mean pair's, and the kernel
#: refuses dt > t_c/10 of the lightest pair (d = 0.9: t_c/11.8 of the mean pair)
CELL_FRACS: tuple[int, ...] = (12, 20, 50, 100, 200)

SCHEMA = {
    "dt_label": pl.Utf8,
    "frac": pl.Float64,
    "dt": pl.Float64,
    "steps": pl.Int64,
    "wall_time": pl.Float64,
    "observable": pl.Utf8,
    "value": pl.Float64,
    "se": pl.Float64,
    "reference": pl.Float64,
    "deviation": pl.Float64,
    "rel_deviation": pl.Float64,
}


def dt_label(frac: float) -> str:
    """``'t_c/50'`` for ``frac = 50``."""
    return f"t_c/{frac:g}"


def _check_fracs(fracs: Sequence[float]) -> list[float]:
    out = sorted({float(f) for f in fracs})
    if not out or any(not (math.isfinite(f) and f >= 10.0) for f in out):
        raise ParameterError(
            f"invalid fracs = {list(fracs)!r}: allowed a non-empty list of numbers >= 10 "
            "(dt = t_c/f; the kernel refuses dt above t_c/10)"
        )
    return out


def _core(obj: Any) -> Any:
    """The kernel handle of a Simulation or a scene (its ``core``; a scene is prepared first,
    :meth:`granflow.scenes.Scene.prepare` does nothing when it is prepared already)."""
    prepare = getattr(obj, "prepare", None)
    if callable(prepare):
        prepare()
    return obj.core


# --------------------------------------------------------------------------------------------
# binary collision
# --------------------------------------------------------------------------------------------
def binary_collision_study(
    fracs: Sequence[float] = DEFAULT_FRACS,
    e_n: float = 0.82,
    kn: float = 1e6,
    form: str = "hooke",
    *,
    phases: int = 16,
    v0: float = 1.0,
    d: tuple[float, float] = (1.0, 1.0),
    repeats: int = 1,
) -> pl.DataFrame:
    """Work-precision table of the binary collision against the analytic ``e_n``.

    For every ``f`` in ``fracs``: ``phases`` collisions with contact onsets at the phases
    ``(k + 1/2)/phases`` of a step (:func:`granflow.analysis.collision.head_on_collision`), repeated
    ``repeats`` times for the timing (the fastest repetition is reported; one untimed collision
    first). Observables: ``e_n`` (phase mean; reference the analytic ``e_n``), ``e_n_max_error``
    (largest ``|e - e_n|`` over the phases; reference 0). ``wall_time`` is the wall time of the
    ``phases`` collisions (kernel calls only: two particles, so mostly per-call overhead);
    ``steps`` the steps of one collision run (until the separation is seen, in chunks of about
    t_c/4).

    With equal spheres the contact lasts exactly ``f`` steps of ``t_c/f``, so it ends at the
    same phase of a step as it began; use an unequal pair (``d = (1.0, 1.2)``: the kernel's
    ``t_c`` is that of the lightest pair, the collision's is longer) to sample end phases
    independently, as in a polydisperse packing.
    """
    fr = _check_fracs(fracs)
    if phases < 1 or repeats < 1:
        raise ParameterError(f"invalid phases/repeats = {phases}/{repeats}: allowed >= 1")
    law = collision_law(e_n, kn, form)
    t_c = law_contact_time(law, np.asarray(d, float))
    head_on_collision(law, t_c / fr[0], v0=v0, d=d, t_c=t_c)  # warm-up, not timed
    rows: list[dict[str, Any]] = []
    for f in fr:
        dt = t_c / f
        best = math.inf
        es: list[float] = []
        steps = 0
        for _ in range(repeats):
            es, wall, steps = [], 0.0, 0
            for k in range(phases):
                c = head_on_collision(law, dt, phase=(k + 0.5) / phases, v0=v0, d=d,
                                      t_c=t_c)
                es.append(c.e_n)
                wall += c.wall_time
                steps = max(steps, c.steps)
            best = min(best, wall)
        ea = np.asarray(es)
        mean = float(ea.mean())
        worst = float(np.max(np.abs(ea - e_n)))
        base = {"dt_label": dt_label(f), "frac": f, "dt": dt, "steps": steps, "wall_time": best}
        rows.append({**base, "observable": "e_n", "value": mean, "se": None, "reference": e_n,
                     "deviation": mean - e_n, "rel_deviation": (mean - e_n) / e_n})
        rows.append({**base, "observable": "e_n_max_error", "value": worst, "se": None,
                     "reference": 0.0, "deviation": worst, "rel_deviation": worst / e_n})
    return pl.DataFrame(rows, schema=SCHEMA)


# --------------------------------------------------------------------------------------------
# generic scene study
# --------------------------------------------------------------------------------------------
#: An observable: ``fn(scene)`` returning a value, or a (value, standard error) pair.
Observable = Callable[[Any], "float | tuple[float, float]"]

#: Attribute a study sets on a scene: samples at or before this time are not averaged.
T_FROM = "_timestep_study_t_from"


def series_mean(column: str) -> Observable:
    """Observable: mean of ``column`` of the scene's ``series`` table over the samples of the
    timed run (after the time stored by :func:`scene_study` in ``scene._timestep_study_t_from``)
    with its blocking standard error (:func:`granflow.analysis.stats.blocking`)."""

    def fn(scene: Any) -> tuple[float, float]:
        from granflow.analysis.stats import blocking

        tabs = scene.tables()
        if "series" not in tabs or column not in tabs["series"].column_names:
            raise ParameterError(
                f"invalid observable {column!r}: not a column of the scene's series table"
            )
        t = tabs["series"]["t"].to_numpy()
        x = tabs["series"][column].to_numpy().astype(float)
        x = x[t > getattr(scene, T_FROM, -math.inf)]
        if x.size == 0:
            raise ParameterError(
                f"invalid observable {column!r}: no samples in the timed run (sample more often)"
            )
        b = blocking(x)
        return float(np.mean(x)), float(b.se)

    fn.__name__ = f"mean_{column}"
    return fn


def _observables(observables: Mapping[str, Observable] | Sequence[str]) -> dict[str, Observable]:
    if isinstance(observables, Mapping):
        return dict(observables)
    return {c: series_mean(c) for c in observables}


def _value_se(v: Any) -> tuple[float, float]:
    if isinstance(v, tuple):
        return float(v[0]), float(v[1])
    return float(v), math.nan


def scene_study(
    factory: Callable[[float | None], Any],
    observables: Mapping[str, Observable] | Sequence[str],
    fracs: Sequence[float] = DEFAULT_FRACS,
    steps_time: float = 1.0,
    *,
    t_c: float | None = None,
    prepare: Callable[[Any], None] | None = None,
) -> pl.DataFrame:
    """Run the same short scene at ``dt = t_c/f`` for every ``f`` in ``fracs`` over the same
    simulated time ``steps_time`` and tabulate each observable's deviation from the finest run.

    Parameters
    ----------
    factory
        ``factory(dt)`` builds the scene (anything with ``run(steps, progress=...)`` and
        ``core``, e.g. a scene of :mod:`granflow.scenes` or a :class:`granflow.Simulation`);
        ``factory(None)`` builds it with its default timestep (used to read ``t_c`` when not
        given). It must start from the same state whatever ``dt``.
    observables
        ``{name: fn(scene)}`` evaluated after the run, returning a value or (value, SE); or
        names of ``series`` columns (:func:`series_mean`: mean over the timed run's samples,
        with its blocking SE).
    fracs
        Timestep fractions (``>= 10``).
    steps_time
        Simulated time of every run (``steps = round(steps_time / dt)``).
    t_c
        Contact time (default: ``factory(None).core.contact_time``).
    prepare
        Called on the scene before the timed run (e.g. a preparation or warm-up at that
        ``dt``); samples up to the end of it are not averaged by :func:`series_mean`.

    ``wall_time`` is the wall time of the timed run alone (construction and ``prepare``
    excluded); ``se`` is the observable's standard error when it has one (a time average),
    null otherwise: a deviation much larger than the SEs is discretisation error, one of the
    order of the SEs is noise (a chaotic many-body run decorrelates from its finer twin).
    """
    fr = _check_fracs(fracs)
    obs = _observables(observables)
    if not obs:
        raise ParameterError("invalid observables: allowed at least one")
    if not (math.isfinite(steps_time) and steps_time > 0):
        raise ParameterError(f"invalid steps_time = {steps_time}: allowed > 0")
    if t_c is None:
        t_c = float(_core(factory(None)).contact_time)
    results: list[tuple[float, float, int, float, dict[str, tuple[float, float]]]] = []
    for f in fr:
        dt = t_c / f
        scene = factory(dt)
        if prepare is not None:
            prepare(scene)
        got = float(_core(scene).dt)
        if abs(got - dt) > 1e-9 * dt:
            raise GranflowError(
                f"the scene runs at dt = {got:.6e}, not the requested t_c/{f:g} = {dt:.6e}: "
                "its factory must build it with the given dt"
            )
        try:
            setattr(scene, T_FROM, float(_core(scene).time))
        except AttributeError:  # a scene with __slots__: average over all samples
            pass
        steps = max(1, round(steps_time / dt))
        t0 = time.perf_counter()
        scene.run(steps, progress=False)
        wall = time.perf_counter() - t0
        vals = {k: _value_se(fn(scene)) for k, fn in obs.items()}
        results.append((f, dt, steps, wall, vals))
    ref = results[-1][4]  # finest dt
    rows: list[dict[str, Any]] = []
    for f, dt, steps, wall, vals in results:
        for k, (v, se) in vals.items():
            r = ref[k][0]
            dev = v - r
            with np.errstate(all="ignore"):
                rel = dev / abs(r) if r != 0 else math.nan
            rows.append({"dt_label": dt_label(f), "frac": f, "dt": dt, "steps": steps,
                         "wall_time": wall, "observable": k, "value": v,
                         "se": None if math.isnan(se) else se, "reference": r,
                         "deviation": dev, "rel_deviation": rel})
    return pl.DataFrame(rows, schema=SCHEMA)


def gas_factory(
    L: float = 8.0,
    phi: float = 0.3,
    kn: float = 1e5,
    e_n: float = 0.8,
    mu: float = 0.5,
    seed: int = 3,
    temperature: float = 1.0,
) -> Callable[[float | None], Simulation]:
    """Factory of a small periodic frictional gas (same initial state for every ``dt``) for
    :func:`scene_study` (kernel check while the papers' scenes are being built)."""
    from granflow.simulation import maxwell_velocities, random_packing
    from granflow.sizes import uniform

    box = Box(length=(L, L, L))
    x, d = random_packing(uniform(0.9, 1.1), box, phi, seed=seed)
    v = maxwell_velocities(len(d), math.sqrt(temperature), seed=seed)

    def make(dt: float | None) -> Simulation:
        return Simulation(x, d, box, ContactLaw(kn=kn, e_n=e_n, mu=mu), velocities=v, dt=dt)

    return make


def kinetic_energy(obj: Any) -> float:
    """Observable: translational + rotational kinetic energy at the end of the run."""
    e = _core(obj).energies()
    return float(e[0] + e[1]) if isinstance(e, tuple) else float(
        e["kinetic_translational"] + e["kinetic_rotational"])


def _cell_class() -> type[Scene]:
    from granflow.scenes import get_scene

    try:
        return get_scene("cell")
    except (ModuleNotFoundError, ParameterError) as exc:
        raise GranflowError(
            "the sheared-packing timestep study needs the stress-controlled cell "
            "(granflow.scenes.cell.ShearCell), which is not available in this build"
        ) from exc


def sheared_packing_study(
    params: Mapping[str, Any] | None = None,
    observables: Mapping[str, Observable] | Sequence[str] = ("mu1", "phi", "I"),
    fracs: Sequence[float] = CELL_FRACS,
    time_tc: float = 1000.0,
    *,
    warmup_tc: float = 1000.0,
    sample_tc: float = 0.5,
    seed: int = 0,
    threads: int | None = None,
) -> pl.DataFrame:
    """:func:`scene_study` on a sheared packing in the stress-controlled cell
    (``granflow.scenes.cell.ShearCell``, paper 002, whose ``dt = f t_c`` with the cell's
    ``t_c``, the collision time of two mean particles; the default ``fracs`` start at 12, since
    the kernel refuses dt above t_c/10 of its lightest pair, ~t_c/11.8 of the mean pair).

    Every timestep ``t_c/f`` runs the same scene (same seed: the same dilute start) with the
    material's dt rule ``DtRule.tc_fraction(1/f)``: ``warmup_tc`` contact times of compaction
    and start-up of the shear flow under ``p_ext`` and ``tau_ratio`` (untimed), then the timed
    ``time_tc`` contact times whose samples (every ``sample_tc`` contact times, so at the same
    times for every ``dt``) give the observables: by default the means of mu1, phi and I of the
    ``series`` table (docs/columns.md) with their blocking SEs. A sheared packing is chaotic, so
    runs at different ``dt`` decorrelate within a few contact times and a warm start from one
    checkpoint would not keep them together; the comparison is therefore between steady
    averages, and a deviation is discretisation error only where it clearly exceeds the SEs
    (lengthen ``time_tc`` to resolve smaller errors). ``params`` go to ``ShearCell.from_spec``
    (default ``N = 250``).

    Raises :class:`granflow.GranflowError` if the cell scene is not available in this build.
    """
    cls = _cell_class()
    base = {"N": 250, **dict(params or {})}
    try:
        probe: Any = cls.from_spec(base, seed=seed, threads=threads)
    except AttributeError as exc:
        if "granflow._core" not in str(exc):
            raise
        raise GranflowError(
            f"the kernel in this build has no cell support yet ({exc}): rebuild granflow"
        ) from exc
    t_c = float(probe.t_c)

    def factory(dt: float | None) -> Any:
        p = dict(base)
        if dt is not None:
            f = t_c / dt
            p.update(material=probe.mat.with_(dt_rule=DtRule.tc_fraction(1.0 / f)),
                     sample_every=max(1, round(sample_tc * f)))
        return cls.from_spec(p, seed=seed, threads=threads)

    def warm(scene: Any) -> None:
        # a whole number of samples, so that the timed run samples at the same times
        every = int(getattr(scene, "sample_every", 1))
        n = round(warmup_tc * t_c / scene.timestep)
        scene.run(every * math.ceil(n / every), progress=False)

    return scene_study(factory, observables, fracs, time_tc * t_c, t_c=t_c, prepare=warm)


# --------------------------------------------------------------------------------------------
# output
# --------------------------------------------------------------------------------------------
def work_precision_plot(table: pl.DataFrame, path: str | os.PathLike[str]) -> Path:
    """Work-precision diagram (|deviation| against wall time, log-log, points labelled by dt):
    :func:`granflow.analysis.plots.plot_work_precision`. Rows with zero deviation (the reference
    run itself) are left out of the log plot."""
    from granflow.analysis.plots import plot_work_precision

    t = table.filter(pl.col("deviation").abs() > 0)
    return plot_work_precision(t, path)


def format_table(table: pl.DataFrame) -> str:
    """Plain-text work-precision table (one line per dt and observable)."""
    lines = [f"{'dt':>9} {'steps':>7} {'wall [s]':>10} {'observable':>16} {'value':>14} "
             f"{'SE':>9} {'deviation':>11}"]
    for r in table.iter_rows(named=True):
        se = "-" if r.get("se") is None else f"{r['se']:.2e}"
        lines.append(
            f"{r['dt_label']:>9} {r['steps']:>7d} {r['wall_time']:>10.3g} "
            f"{r['observable']:>16} {r['value']:>14.8g} {se:>9} {r['deviation']:>11.3e}"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m granflow.studies.timestep [--out DIR]``: binary-collision studies (linear and
    Hertz laws; equal spheres and a 1 : 1.2 pair, whose contact is not a whole number of steps);
    prints the tables and writes Parquet and PNG when ``--out`` is given."""
    import argparse

    from granflow.io import write_parquet

    ap = argparse.ArgumentParser(prog="python -m granflow.studies.timestep",
                                 description=main.__doc__)
    ap.add_argument("--out", default=None, help="directory for timestep_*.parquet / .png")
    ap.add_argument("--e-n", type=float, default=0.82)
    ap.add_argument("--kn", type=float, default=1e6)
    ap.add_argument("--phases", type=int, default=16)
    a = ap.parse_args(argv)
    for form in ("hooke", "hertz"):
        for d in ((1.0, 1.0), (1.0, 1.2)):
            t = binary_collision_study(e_n=a.e_n, kn=a.kn, form=form, phases=a.phases, d=d,
                                       repeats=3)
            tag = f"{form}_{d[0]:g}_{d[1]:g}"
            print(f"binary collision, {form}, d = {d}, e_n = {a.e_n}, kn = {a.kn:g}, "
                  f"{a.phases} contact-onset phases")
            print(format_table(t))
            if a.out:
                out = Path(a.out)
                params = {"study": "binary_collision", "form": form, "e_n": a.e_n, "kn": a.kn,
                          "d": list(d), "phases": a.phases}
                write_parquet(t.to_arrow(), out / f"timestep_collision_{tag}.parquet",
                              params=params)
                work_precision_plot(t, out / f"timestep_collision_{tag}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
