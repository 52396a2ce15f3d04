"""The campaign engine: a dataset directory of Parquet tables that grows one finished point at
a time, and the resumable loop that runs a point in stints.

A study implements :class:`Study` (one instance, picklable: the pool sends it to its
workers); the loop (:func:`run_point`) is, for each point in ``OUT/work/<key>/``: restore its
checkpoint and tables, or build and prepare the scene; then stints of
:meth:`Study.next_steps` steps, each followed by writing the scene's tables, checkpoint and
``meta.json`` (wall and CPU time, preparation time, the stints' states and the row's context),
the point's row (:meth:`Study.row`), the one stop rule (:meth:`Study.stop`), which
:func:`reanalyse` calls too, and a copy of the work directory in the committed
``OUT/progress/<key>/`` (:mod:`.progress`: a work directory lost with its machine is restored
from there). A :class:`~granflow.errors.GranflowError` ends a point with
``state`` "runaway" (a :class:`~granflow.errors.DilationError`) or "failed" and the error.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import polars as pl
import pyarrow as pa

from granflow.errors import DilationError, GranflowError

from . import progress

#: the lock file of a dataset directory (:func:`dataset_lock`)
LOCK_NAME = ".lock"


@contextlib.contextmanager
def dataset_lock(out: str | os.PathLike[str]) -> Iterator[None]:
    """Hold the dataset directory ``out`` for one process at a time while it reads and
    rewrites its tables: the documented way to run a campaign's points side by side is a
    process per point into one ``OUT``, and each appends its finished row by reading the
    table and writing it whole (:func:`write_rows`), so two finishing together would lose a
    row. An advisory ``flock`` on ``OUT/.lock`` (released with the process, so a crash
    leaves no stale lock); where the platform has no ``fcntl``, no lock."""
    try:
        import fcntl
    except ImportError:  # (not POSIX)
        yield
        return
    outp = Path(out)
    outp.mkdir(parents=True, exist_ok=True)
    with open(outp / LOCK_NAME, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def write_rows(f: Path, rows: Sequence[Mapping[str, Any]], append: bool = False,
               point: type | None = None) -> None:
    """Write ``rows`` as the Parquet table ``f`` (atomically), after its rows if ``append``;
    columns missing from some rows are null there. Nothing is written for no rows. ``point``:
    the point's dataclass, whose field names go to the file's metadata (the coverage audit,
    :mod:`granflow.analysis.coverage`, groups the replicas by them)."""
    from granflow import io
    from granflow.analysis.coverage import POINT_FIELDS_KEY

    if not rows:
        return
    new = pl.from_dicts(list(rows), infer_schema_length=None)
    if append and f.exists():
        new = pl.concat([pl.read_parquet(f), new], how="diagonal_relaxed")
    new = with_defaults(new, point)
    tab = new.to_arrow()
    if point is not None and dataclasses.is_dataclass(point):
        names = json.dumps([x.name for x in dataclasses.fields(point)]).encode()
        tab = tab.replace_schema_metadata({**(tab.schema.metadata or {}),
                                           POINT_FIELDS_KEY: names})
    io.write_parquet(tab, f)


def with_defaults(table: pl.DataFrame, point: type | None) -> pl.DataFrame:
    """``table`` with the fields of the dataclass ``point`` that it lacks, or that some of its
    rows lack (rows written before the field was added), set to the field's default, the
    value :func:`point_of` gives them: the replicas of a point then group the same in old
    rows and new."""
    if point is None or not dataclasses.is_dataclass(point):
        return table
    fill = [x for x in dataclasses.fields(point) if x.default is not dataclasses.MISSING
            and (x.name not in table.columns or table[x.name].null_count())]
    return table.with_columns(
        (pl.col(x.name).fill_null(x.default) if x.name in table.columns
         else pl.lit(x.default)).alias(x.name) for x in fill)


def point_of(cls: type, row: Mapping[str, Any]) -> Any:
    """The point (dataclass ``cls``) a row of ``points.parquet`` was run for; a field the row
    lacks (a dataset written before the field was added) takes the field's default, which
    must then be what those runs used."""
    return cls(**{f.name: row[f.name] for f in dataclasses.fields(cls) if f.name in row})


def done_keys(out: Path, cls: type, study: Study | None = None) -> set[str]:
    """Keys of the points already in ``out/points.parquet`` (with ``study``: those whose row
    counts as done, :func:`is_current`)."""
    f = out / "points.parquet"
    return keys_done(pl.read_parquet(f), cls, study) if f.exists() else set()


def keys_done(points: pl.DataFrame, cls: type, study: Study | None = None) -> set[str]:
    """:func:`done_keys` of a points table already read."""
    return {point_of(cls, r).key for r in points.iter_rows(named=True)
            if study is None or is_current(study, r)}


def is_current(study: Study, row: Mapping[str, Any]) -> bool:
    """Whether a finished ``row`` counts as done: one that ended on an error (ERROR_STATES)
    always (no stop rule judged it, under any rule, and its row carries none of the rule's
    fields), else :meth:`Study.current`."""
    return row.get("state") in ERROR_STATES or study.current(row)


def drop_key(f: Path, cls: type, key: str) -> None:
    """Remove the rows of the point ``key`` from the table ``f`` (a point's row, or its rows
    of a further table, about to be replaced by a new run's)."""
    if not f.exists():
        return
    d = pl.read_parquet(f)
    keys = [point_of(cls, r).key for r in d.iter_rows(named=True)]
    if key not in keys:
        return
    rest = list(d.filter(pl.Series([k != key for k in keys])).iter_rows(named=True))
    if rest:
        write_rows(f, rest, point=cls)
    else:
        f.unlink()


def fmt(row: Mapping[str, Any], key: str, spec: str = ".4g") -> str:
    """``row[key]`` formatted for a progress line; ``-`` while it is missing or not yet
    measured (NaN: too few blocks so far), so the line never prints ``nan``."""
    v = row.get(key)
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return format(v, spec)


class Study:
    """What a study gives the engine. A point is a frozen dataclass with a ``key`` property
    (the name of its work directory); a plan is the study's settings (its stints in time
    units of the scene, converted to steps by :meth:`next_steps`). Subclasses implement
    :meth:`scene`, :meth:`next_steps`, :meth:`row` and :meth:`stop`; the rest has defaults."""

    #: rows returned under these keys of a point's row go to ``OUT/<stem>.parquet``
    tables: Mapping[str, str] = {}
    #: the keys of :attr:`tables` whose rows :meth:`final` gives (not :meth:`row`)
    final_tables: tuple[str, ...] = ()

    def scene(self, point: Any, plan: Any, threads: int) -> Any:
        """The point's scene, built (not yet prepared): the one place a study builds it."""
        raise NotImplementedError

    def start(self, scene: Any, point: Any, plan: Any, work: Path) -> None:
        """Prepare a new scene (not called after a restore); ``work`` holds every point's
        directory (a branch starts from another point's checkpoint there)."""
        scene.prepare(progress=False)

    def starts_from(self, point: Any) -> tuple[str, ...]:
        """The keys of the points whose final state :meth:`start` begins ``point`` from
        (restored into their work directories from their kept copies if need be); none by
        default."""
        return ()

    def dependents(self, key: str, plan: Any) -> tuple[str, ...]:
        """The keys of the points of ``plan`` that start from the final state of the point
        ``key`` (:meth:`starts_from`): its kept copy stays until they are all done."""
        return ()

    def kept_tables(self, point: Any, plan: Any,
                    tables: Mapping[str, pa.Table]) -> Mapping[str, pa.Table]:
        """The part of the point's tables that its committed copy (:mod:`.progress`) holds:
        all of them by default; a study whose rows read less may keep less (its rows from
        the kept part must equal those from the whole)."""
        return tables

    def next_steps(self, scene: Any, point: Any, plan: Any) -> int:
        """Steps of the next stint: the plan's stint, cut at the point's budget; 0 once the
        budget is spent."""
        raise NotImplementedError

    def context(self, scene: Any) -> dict[str, Any]:
        """What :meth:`row` needs beyond the tables (kept in ``meta.json``, for
        :func:`reanalyse`)."""
        return {}

    def progress(self, scene: Any, prep_seconds: float) -> dict[str, Any]:
        """How far the point ran (steps, time, ...): fields the row ends with (before
        ``wall_seconds``), and that :meth:`stop` reads."""
        return {}

    def row(self, point: Any, plan: Any, tables: Mapping[str, pa.Table],
            context: Mapping[str, Any]) -> dict[str, Any]:
        """The point's row from its tables: the point's fields, ``state``, ``converged`` and
        the measurements; the rows of further tables under the keys of :attr:`tables`."""
        raise NotImplementedError

    def final(self, point: Any, scene: Any) -> dict[str, list[dict[str, Any]]]:
        """Rows of the tables :attr:`final_tables` measured once on a point's last state,
        after its last stint (a snapshot's analysis): nothing by default. Also
        what :func:`add_final_rows` gives a finished point from its checkpoint."""
        return {}

    def failure(self, scene: Any, context: Mapping[str, Any]) -> dict[str, Any]:
        """Further fields of the row of a point that ended with an error."""
        return {}

    def stop(self, row: Mapping[str, Any], point: Any, plan: Any,
             history: Sequence[str]) -> str | None:
        """Why the point is done after the stint that gave ``row`` (with its :meth:`progress`
        fields), e.g. "converged", "arrested" or "budget"; None to go on. ``history``: the
        states of the earlier stints, oldest first."""
        raise NotImplementedError

    def describe(self, row: Mapping[str, Any]) -> str:
        """A point's progress line from its ``row`` (after a stint, with ``wall_seconds`` and
        ``cpu_seconds`` so far, and when it is done): its state by default."""
        return str(row.get("state"))

    def current(self, row: Mapping[str, Any]) -> bool:
        """Whether a finished ``row`` of the dataset counts as done: judged by the present
        stop rule. One that does not (written before the rule) is run again, and the new row
        replaces it (:func:`run_points`). Rows that ended on an error are done whatever this
        says (:func:`is_current`)."""
        return True


#: the states of points that ended on an error (:func:`error_state`)
ERROR_STATES = ("runaway", "failed")


def error_state(exc: GranflowError) -> str:
    """The state of a point ended by ``exc``: "runaway" for the cell's runaway dilation,
    "failed" for any other error."""
    return "runaway" if isinstance(exc, DilationError) else "failed"


def _read_tables(d: Path) -> dict[str, pa.Table]:
    import pyarrow.parquet as pq

    return {f.stem: pq.read_table(f) for f in sorted(d.glob("*.parquet"))}


def run_point(study: Study, point: Any, plan: Any, work: str,
              threads: int = 1) -> dict[str, Any]:
    """Run (or go on with) ``point`` in ``work/<key>`` in stints until ``study.stop`` says it
    is done or the budget is spent (``study.next_steps`` gives 0); returns its row."""
    from granflow import io

    d = Path(work) / point.key
    d.mkdir(parents=True, exist_ok=True)
    ck, meta = d / "checkpoint.gfck", d / "meta.json"
    copy = kept_dir(work, point.key)
    if progress.ahead(copy, d):
        progress.restore(copy, d)
    scene = study.scene(point, plan, threads)
    # (cpu_seconds: the process's CPU time over the point, all its threads: its core-seconds
    # whatever else shares the cores, where wall_seconds counts the waits as well)
    info: dict[str, Any] = {"wall_seconds": 0.0, "cpu_seconds": 0.0, "prep_seconds": math.nan}
    restored = ck.exists() and meta.exists()
    if restored:
        scene.restore(ck)
        scene.load_tables(_read_tables(d))
        kept = json.loads(meta.read_text())
        # (a work directory from before cpu_seconds: its CPU time so far is unknown)
        info.update({"cpu_seconds": math.nan, **kept})
    t0, c0 = time.perf_counter(), time.process_time()
    if not restored:
        for key in study.starts_from(point):
            if progress.ahead(kept_dir(work, key), Path(work) / key):
                progress.restore(kept_dir(work, key), Path(work) / key)
        study.start(scene, point, plan, Path(work))
        info["prep_seconds"] = time.perf_counter() - t0
    context = study.context(scene)
    history: list[str] = list(info.get("history", []))

    def wall() -> float:
        return float(info["wall_seconds"]) + time.perf_counter() - t0

    def cpu() -> float:
        return float(info.get("cpu_seconds", math.nan)) + time.process_time() - c0

    def write_meta() -> None:
        # (io._jsonable: a study's progress fields may hold numpy scalars)
        meta.write_text(json.dumps(io._jsonable({**info, "wall_seconds": wall(),
                                                 "cpu_seconds": cpu(), "history": history,
                                                 "context": context})))

    error: GranflowError | None = None
    row: dict[str, Any] = {}
    try:
        while (steps := study.next_steps(scene, point, plan)) > 0:
            scene.run(steps, progress=False)
            tables = scene.tables()
            for name, tab in tables.items():
                io.write_parquet(tab, d / f"{name}.parquet")
            scene.save_checkpoint(ck)
            write_meta()  # (a checkpoint is never without its meta, even before the row)
            row = study.row(point, plan, tables, context)
            info["progress"] = study.progress(scene, info["prep_seconds"])
            row.update(info["progress"])
            done = study.stop(row, point, plan, history)
            history.append(str(row["state"]))
            write_meta()
            progress.keep(d, copy, study.kept_tables(point, plan, tables))
            # (a point runs for hours: a line a stint, flushed, from whichever worker runs it)
            print(f"  {point.key} stint {len(history)}: "
                  f"{study.describe({**row, 'wall_seconds': wall(), 'cpu_seconds': cpu()})}"
                  + (f"; done ({done})" if done is not None else ""), flush=True)
            if done is not None:
                break
    except GranflowError as exc:
        error = exc
    if error is not None or not row:
        row = study.row(point, plan, scene.tables(), context)
    if error is None:
        row.update(study.final(point, scene))
    if error is not None:
        row.update(state=error_state(error), error=f"{type(error).__name__}: {error}",
                   converged=False, **study.failure(scene, context),
                   **{k: [] for k in study.tables})
    row.update(study.progress(scene, info["prep_seconds"]), wall_seconds=wall(),
               cpu_seconds=cpu())
    return row


def kept_dir(work: str | os.PathLike[str], key: str) -> Path:
    """Where the point ``key`` of the campaign whose work directories are in ``work``
    (``OUT/work``) keeps its committed copy between stints: ``OUT/progress/<key>``."""
    return Path(work).parent / "progress" / key


def reanalyse(study: Study, cls: type, plan: Any, out: str | os.PathLike[str]) -> int:
    """Recompute the rows of ``out/points.parquet`` (and its other tables) from the tables kept
    in ``out/work`` (after a change of the analysis), with the rows' :meth:`Study.progress`
    fields as they were; a point the stop rule no longer stops is dropped, so that the next
    run goes on with it from its checkpoint. Points that ended with an error, or without a
    work directory, are kept as they are, with their rows of the other tables; so are the
    rows a recomputed row does not give (:meth:`Study.final`'s). Returns the number of
    points dropped. Holds the dataset (:func:`dataset_lock`) from its reading to its
    writing."""
    with dataset_lock(out):
        return _reanalyse(study, cls, plan, Path(out))


def _reanalyse(study: Study, cls: type, plan: Any, outp: Path) -> int:
    keep: list[dict[str, Any]] = []
    old_rows = {k: _rows_by_key(outp / f"{stem}.parquet", cls) for k, stem in
                study.tables.items()}
    extra: dict[str, list[dict[str, Any]]] = {k: [] for k in study.tables}
    dropped = 0
    for old in pl.read_parquet(outp / "points.parquet").iter_rows(named=True):
        point = point_of(cls, old)
        d = outp / "work" / point.key
        # (a work directory restored from a slimmed copy, for a branch, holds no tables)
        if (not (d / "meta.json").exists() or old["state"] in ERROR_STATES
                or not any(d.glob("*.parquet"))):
            keep.append(old)
            for k in study.tables:
                extra[k] += old_rows[k].get(point.key, [])
            continue
        info = json.loads((d / "meta.json").read_text())
        row = {**old, **study.row(point, plan, _read_tables(d), _context(info, d))}
        # (a work directory from before the engine kept no history: the loop had stopped on
        # the old row's state, so that was the earlier stint's too)
        earlier = info["history"][:-1] if "history" in info else [old["state"]]
        if study.stop(row, point, plan, earlier) is None:
            dropped += 1
            continue
        for k in study.tables:
            extra[k] += row.pop(k) if k in row else old_rows[k].get(point.key, [])
        keep.append(row)
    for f, rows in ((outp / "points.parquet", keep),
                    *((outp / f"{stem}.parquet", extra[k]) for k, stem in study.tables.items())):
        if rows:
            write_rows(f, rows, point=cls)
        else:  # (every row dropped: write_rows writes nothing for none)
            f.unlink(missing_ok=True)
    return dropped


def _rows_by_key(f: Path, cls: type) -> dict[str, list[dict[str, Any]]]:
    """The rows of table ``f`` per point key (none if there is no ``f``)."""
    out: dict[str, list[dict[str, Any]]] = {}
    if f.exists():
        for r in pl.read_parquet(f).iter_rows(named=True):
            out.setdefault(point_of(cls, r).key, []).append(r)
    return out


def add_final_rows(study: Study, cls: type, plan: Any, out: str | os.PathLike[str]) -> int:
    """Give the finished points of ``out`` that lack them the rows of :meth:`Study.final`,
    measured on the last state kept in their work directory (points finished before the
    study measured them; one without a checkpoint stays without). Returns how many points
    gained rows. Holds the dataset (:func:`dataset_lock`) throughout."""
    with dataset_lock(out):
        return _add_final_rows(study, cls, plan, Path(out))


def _add_final_rows(study: Study, cls: type, plan: Any, outp: Path) -> int:
    f = outp / "points.parquet"
    if not f.exists():
        return 0
    have: dict[str, set[str]] = {k: set(_rows_by_key(outp / f"{stem}.parquet", cls))
                                 for k, stem in study.tables.items()}
    added = 0
    for old in pl.read_parquet(f).iter_rows(named=True):
        point = point_of(cls, old)
        ck = outp / "work" / point.key / "checkpoint.gfck"
        if old["state"] in ERROR_STATES or not ck.exists():
            continue
        missing = [k for k in study.final_tables if point.key not in have[k]]
        if not missing:
            continue
        scene = study.scene(point, plan, 1)
        scene.restore(ck)
        rows = study.final(point, scene)
        for k in missing:
            write_rows(outp / f"{study.tables[k]}.parquet", rows[k], append=True, point=cls)
        added += 1
    return added


def _context(info: Mapping[str, Any], d: Path) -> dict[str, Any]:
    """The row's context kept in ``meta.json``; for a work directory from before the engine,
    the checkpoint header's metadata (the cell's ``shear_start_time``)."""
    if "context" in info:
        return dict(info["context"])
    from granflow import _core

    try:
        header = _core.read_checkpoint_header(os.fspath(d / "checkpoint.gfck"))[1]
    except GranflowError:
        return {}
    return dict(json.loads(header or "{}"))


def run_points(study: Study, points: Sequence[Any], plan: Any, out: str | os.PathLike[str], *,
               workers: int | None = None, scheduler: str | None = None,
               threads: int | None = None, log: Callable[[str], Any] = print,
               name: str = "campaign", whole: Any = None) -> pl.DataFrame:
    """Run (:func:`run_point`) the ``points`` not yet done in ``out/points.parquet`` (local
    process pool by default, or a Dask scheduler): those it lacks, and those whose row is not
    :func:`is_current` (the new row replaces the old, in every table); each finished row is
    appended there at once, and the
    list of rows under each key ``k`` of ``study.tables`` to ``out/<study.tables[k]>.parquet``.
    ``threads`` per point (default cores/workers; :func:`granflow.study.map_tasks`).
    ``whole``: the plan that ``plan`` is a piece of (``--select``; default ``plan``), whose
    points keep a finished point's copy while they start from it (:meth:`Study.dependents`),
    selected or not. Returns the whole points table."""
    from granflow.study import map_tasks

    outp = Path(out)
    outp.mkdir(parents=True, exist_ok=True)
    cls = type(points[0]) if points else object
    done = done_keys(outp, cls, study) if points else set()
    stale = (done_keys(outp, cls) - done) if points else set()
    todo = [p for p in points if p.key not in done]
    rerun = sum(p.key in stale for p in todo)
    log(f"{name}: {len(points)} points, {len(points) - len(todo)} done, {len(todo)} to run"
        + (f" ({rerun} of them again: rows from before the present stop rule)"
           if rerun else ""))
    args = [(study, p, plan, str(outp / "work")) for p in todo]
    finished = set(done)

    def tidy(key: str) -> None:
        # (a finished point's kept copy goes once no unfinished point starts from it; until
        # then it keeps only the checkpoint they start from)
        if key not in finished:
            return
        kept = kept_dir(outp / "work", key)
        if all(k in finished for k in study.dependents(key, plan if whole is None else whole)):
            progress.forget(kept)
            return
        if not kept.exists():
            # (a copy that a piece of the campaign forgot, not seeing the branches: kept
            # again from the work directory where that still holds the final state)
            progress.keep(outp / "work" / key, kept, {})
        progress.slim(kept)

    for p in points:
        tidy(p.key)
    for _, row in map_tasks(run_point, args, workers=workers, scheduler=scheduler,
                            threads=threads):
        extras = {stem: row.pop(k, []) for k, stem in study.tables.items()}
        key = point_of(cls, row).key
        append_point(outp, cls, row, extras, replace=key in stale)
        finished.add(key)
        for k in (key, *study.starts_from(point_of(cls, row))):
            tidy(k)
        log(f"  {key}: {study.describe(row)}")
    f = outp / "points.parquet"
    return pl.read_parquet(f) if f.exists() else pl.DataFrame()


def append_point(out: Path, cls: type, row: Mapping[str, Any],
                 extras: Mapping[str, Sequence[Mapping[str, Any]]], *,
                 replace: bool = False) -> None:
    """Append a finished point's ``row`` to ``out/points.parquet`` and its rows of further
    tables (``extras``: file stem -> rows) to theirs, holding the dataset
    (:func:`dataset_lock`); ``replace``: first drop the point's old rows from each (a row from
    before the present stop rule)."""
    with dataset_lock(out):
        if replace:
            key = point_of(cls, row).key
            for f in (out / "points.parquet", *(out / f"{stem}.parquet" for stem in extras)):
                drop_key(f, cls, key)
        write_rows(out / "points.parquet", [row], append=True, point=cls)
        for stem, rows in extras.items():
            write_rows(out / f"{stem}.parquet", rows, append=True, point=cls)


def point_fields(plan: Any) -> dict[str, tuple[Any, ...]]:
    """The fields of the dataclass ``plan`` that are tuples of points (points have a ``key``):
    a cell plan's ``points``; reproduce_000's ``points``, ``branches`` and ``later``."""
    return {f.name: v for f in dataclasses.fields(plan)
            if isinstance(v := getattr(plan, f.name), tuple) and v and hasattr(v[0], "key")}


def plan_points(plan: Any) -> list[Any]:
    """Every point of ``plan`` (:func:`point_fields`), in its order."""
    return [p for v in point_fields(plan).values() for p in v]


def status(out: str | os.PathLike[str], plan: Any) -> pl.DataFrame:
    """Where each started, unfinished point of ``plan`` stands in the dataset ``out``: a row
    per point with a work directory (``OUT/work/<key>``) or a committed copy
    (``OUT/progress/<key>``), whichever has run more stints (``where``), with its stints, the
    last stint's state, how far it ran (``t_run``, where its meta.json records the study's
    progress fields) and its wall and CPU seconds so far. A point with a row in
    ``points.parquet`` is left out."""
    outp = Path(out)
    points = plan_points(plan)
    done = done_keys(outp, type(points[0])) if points else set()
    rows = []
    for key in dict.fromkeys(p.key for p in points):
        if key in done:
            continue
        metas = [(where, json.loads(m.read_text()))
                 for where, m in (("work", outp / "work" / key / "meta.json"),
                                  ("progress", kept_dir(outp / "work", key) / "meta.json"))
                 if m.exists()]
        if not metas:
            continue
        where, m = max(metas, key=lambda wm: len(wm[1].get("history", [])))
        hist = m.get("history", [])
        rows.append({"key": key, "where": where, "stints": len(hist),
                     "state": hist[-1] if hist else None,
                     "t_run": m.get("progress", {}).get("t_run"),
                     "wall_seconds": m.get("wall_seconds"),
                     "cpu_seconds": m.get("cpu_seconds")})
    return pl.DataFrame(rows, schema={"key": pl.String, "where": pl.String,
                                      "stints": pl.Int64, "state": pl.String,
                                      "t_run": pl.Float64, "wall_seconds": pl.Float64,
                                      "cpu_seconds": pl.Float64})
