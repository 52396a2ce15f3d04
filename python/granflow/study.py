"""Parameter sweeps: a grid of runs (with seeds) executed in parallel on this machine (a
process pool, one simulation per worker, cores split between workers) or on a Dask distributed
cluster when given a scheduler address. Results land in one hive-partitioned dataset
(``root/key=value/.../seed=s/``) that polars, pyarrow and DuckDB read as one; finished runs are
skipped when a sweep is restarted.
"""

from __future__ import annotations

import copy
import itertools
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import polars as pl

from granflow.errors import GranflowError, ParameterError
from granflow.io import hive_dir
from granflow.runner import execute, validate_spec


def check_grid(base: Mapping[str, Any], grid: Mapping[str, Any]) -> None:
    """Refuse a grid before anything runs: at least one key, each a parameter of the base
    spec's scene, each with a non-empty list of values."""
    if not grid:
        raise ParameterError("invalid grid = {}: allowed at least one parameter with a list "
                             "of values")
    from granflow.scenes import get_scene

    cls = get_scene(str(base.get("scene")))
    known = ({f.name for f in fields(cls)} - {"seed", "threads"}) if is_dataclass(cls) else None
    for k, v in grid.items():
        if known is not None and k not in known:
            raise ParameterError(f"invalid grid key {k!r}: scene {base.get('scene')!r} has no "
                                 f"such parameter; allowed one of {sorted(known)}")
        if isinstance(v, (str, bytes)) or not isinstance(v, Sequence) or len(v) == 0:
            raise ParameterError(f"invalid grid.{k} = {v!r}: allowed a non-empty list of values")


def expand(
    base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]], seeds: Sequence[int]
) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """All (partition, spec) pairs of the grid: each grid key sets ``spec['params'][key]``."""
    if not seeds:
        raise ParameterError("invalid seeds = []: allowed at least one seed")
    keys = list(grid)
    out = []
    for values in itertools.product(*(grid[k] for k in keys)):
        for seed in seeds:
            spec = copy.deepcopy(dict(base))
            spec.setdefault("params", {})
            for k, v in zip(keys, values, strict=True):
                spec["params"][k] = v
            spec["seed"] = int(seed)
            part = {**dict(zip(keys, values, strict=True)), "seed": int(seed)}
            out.append((part, validate_spec(spec)))
    return out


def _one(spec: dict[str, Any], directory: str, threads: int) -> dict[str, Any]:
    """Run one point of the grid; a run that fails (e.g. goes unstable) is recorded with its
    error message instead of stopping the sweep."""
    try:
        r = execute(spec, directory, progress=False, threads=threads)
    except GranflowError as exc:
        return {"status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "directory": directory}
    row = {"status": r.status, "wall_seconds": r.wall_seconds, "directory": str(r.directory)}
    for k, v in r.summary.items():
        if isinstance(v, (int, float, str, bool)) or v is None:
            row[k] = v
    return row


def _die_with_parent() -> None:
    """A pool worker's start: ask Linux to end it with its parent. A parent killed outright
    (SIGTERM, SIGKILL) leaves its workers running their tasks otherwise, orphans that go on
    writing the same run directories as the next sweep (found with a stopped campaign).
    SIGKILL, not SIGTERM: a task inside a run turns SIGTERM into a clean stop of that run
    (simulation.run_chunked), and the worker then takes the next queued task; orphans of a
    stopped campaign ran its queued points for an hour beside the next campaign that way."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        ctypes.CDLL(None).prctl(1, int(signal.SIGKILL))  # 1 = PR_SET_PDEATHSIG


def map_tasks(fn: Callable[..., Any], args: Sequence[tuple[Any, ...]],
              workers: int | None = None,
              scheduler: str | Any | None = None,
              threads: int | None = None) -> Iterator[tuple[int, Any]]:
    """``fn(*a, threads)`` for every ``a`` in ``args``, yielded as ``(index, result)`` as each
    finishes (so a caller can keep every finished result when the rest is stopped).

    Locally ``workers`` processes (default: one per core, at most one per task), each run with
    ``threads`` threads (default cores/workers: set it where other work shares the cores);
    with ``scheduler`` (a Dask scheduler address or a ``distributed.Client``) there, one
    thread each."""
    if threads is not None and threads < 1:
        raise ParameterError(f"invalid threads = {threads}: allowed an integer >= 1")
    if not args:
        return
    if scheduler is not None:
        from distributed import Client
        from distributed import as_completed as dask_completed

        client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
        try:
            futs = {client.submit(fn, *a, 1, pure=False): i for i, a in enumerate(args)}
            for fut in dask_completed(futs):
                yield futs[fut], fut.result()
        finally:
            if client is not scheduler:
                client.close()
        return
    ncores = os.cpu_count() or 1
    workers = workers or min(ncores, len(args))
    threads = threads or max(1, ncores // workers)
    if workers == 1:
        for i, a in enumerate(args):
            yield i, fn(*a, threads)
        return
    # spawn, not fork: forking a process whose Rust thread pool is running deadlocks
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                             initializer=_die_with_parent) as ex:
        pending = {ex.submit(fn, *a, threads): i for i, a in enumerate(args)}
        for fut in as_completed(pending):
            yield pending[fut], fut.result()


def run_grid(
    base: Mapping[str, Any],
    grid: Mapping[str, Sequence[Any]],
    root: str | os.PathLike,
    seeds: Sequence[int] = (0,),
    workers: int | None = None,
    scheduler: str | Any | None = None,
    threads: int | None = None,
) -> pl.DataFrame:
    """Run every combination of ``grid`` (and seed) and return one row per run.

    ``workers`` defaults to the number of cores (each run then gets ``threads`` threads,
    default cores/workers);
    ``scheduler`` is a Dask scheduler address (or a ``distributed.Client``) to run there."""
    check_grid(validate_spec(base), grid)
    tasks = expand(base, grid, seeds)
    root = Path(root)
    dirs = [str(hive_dir(root, part)) for part, _ in tasks]
    rows: list[dict[str, Any]] = [{} for _ in tasks]
    args = [(spec, dd) for (_, spec), dd in zip(tasks, dirs, strict=True)]
    for i, row in map_tasks(_one, args, workers=workers, scheduler=scheduler,
                             threads=threads):
        rows[i] = row
    parts = [part for part, _ in tasks]
    return pl.DataFrame([{**p, **r} for p, r in zip(parts, rows, strict=True)])
