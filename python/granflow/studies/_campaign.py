"""What the reproduction campaigns share: a dataset directory of Parquet tables that grow one
finished point at a time, and the loop that runs the points not yet in it.

A campaign's points are frozen dataclasses with a ``key`` property (the name of their work
directory); a finished point is one row of ``OUT/points.parquet`` holding the point's fields,
and whatever else the study's ``run_point`` returns. Extra tables (lists of rows under keys
of the returned row, e.g. ``"se_rows"``) are appended to their own Parquet files with the
row, so a campaign that is stopped loses only its unfinished points. Also the reports'
markdown helpers (:func:`md_table`, :func:`pm`).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import polars as pl


def write_rows(f: Path, rows: Sequence[Mapping[str, Any]], append: bool = False) -> None:
    """Write ``rows`` as the Parquet table ``f`` (atomically), after its rows if ``append``;
    columns missing from some rows are null there. Nothing is written for no rows."""
    from granflow import io

    if not rows:
        return
    new = pl.from_dicts(list(rows), infer_schema_length=None)
    if append and f.exists():
        new = pl.concat([pl.read_parquet(f), new], how="diagonal_relaxed")
    io.write_parquet(new.to_arrow(), f)


def point_of(cls: type, row: Mapping[str, Any]) -> Any:
    """The point (dataclass ``cls``) a row of ``points.parquet`` was run for."""
    return cls(**{f.name: row[f.name] for f in dataclasses.fields(cls)})


def done_keys(out: Path, cls: type) -> set[str]:
    """Keys of the points already in ``out/points.parquet``."""
    f = out / "points.parquet"
    if not f.exists():
        return set()
    return {point_of(cls, r).key for r in pl.read_parquet(f).iter_rows(named=True)}


def fmt(row: Mapping[str, Any], key: str, spec: str = ".4g") -> str:
    """``row[key]`` formatted, ``nan`` when missing (progress lines)."""
    v = row.get(key)
    return format(v if v is not None else math.nan, spec)


def run_points(points: Sequence[Any], run_point: Callable[..., dict[str, Any]],
               extra: Sequence[Any], out: str | os.PathLike[str], *,
               tables: Mapping[str, str] | None = None, workers: int | None = None,
               scheduler: str | None = None, describe: Callable[[dict[str, Any]], str] = str,
               log: Callable[[str], Any] = print, name: str = "campaign") -> pl.DataFrame:
    """Run ``run_point(point, *extra, OUT/work, threads)`` for the points not yet in
    ``out/points.parquet`` (local process pool by default, or a Dask scheduler); each finished
    row is appended there at once, and the list of rows under each key ``k`` of ``tables`` to
    ``out/<tables[k]>.parquet``.
    Returns the whole points table."""
    from granflow.study import map_tasks

    outp = Path(out)
    outp.mkdir(parents=True, exist_ok=True)
    cls = type(points[0]) if points else object
    done = done_keys(outp, cls) if points else set()
    todo = [p for p in points if p.key not in done]
    log(f"{name}: {len(points)} points, {len(points) - len(todo)} done, {len(todo)} to run")
    args = [(p, *extra, str(outp / "work")) for p in todo]
    for _, row in map_tasks(run_point, args, workers=workers, scheduler=scheduler):
        extras = {stem: row.pop(k, []) for k, stem in (tables or {}).items()}
        write_rows(outp / "points.parquet", [row], append=True)
        for stem, rows in extras.items():
            write_rows(outp / f"{stem}.parquet", rows, append=True)
        log(f"  {point_of(cls, row).key}: {describe(row)}")
    f = outp / "points.parquet"
    return pl.read_parquet(f) if f.exists() else pl.DataFrame()


def md_table(df: pl.DataFrame, fmt: Mapping[str, str] | None = None) -> str:
    """``df`` as a markdown table; floats with ``fmt[column]`` (default .4g), NaN as -."""
    fmt = fmt or {}
    head = "| " + " | ".join(df.columns) + " |"
    sep = "|" + "---|" * len(df.columns)
    body = []
    for r in df.iter_rows(named=True):
        cells = []
        for c in df.columns:
            v = r[c]
            if isinstance(v, float):
                cells.append("-" if not math.isfinite(v) else format(v, fmt.get(c, ".4g")))
            else:
                cells.append(str(v))
        body.append("| " + " | ".join(cells) + " |")
    return "\n".join([head, sep, *body])


def pm(v: float, e: float, digits: int = 3) -> str:
    """``v ± e`` with ``digits`` decimals (``-`` for NaN; ``v`` alone without an error)."""
    if not math.isfinite(v):
        return "-"
    return f"{v:.{digits}f} ± {e:.{digits}f}" if math.isfinite(e) else f"{v:.{digits}f}"


def dask_recipe(module: str, out: str, walltime: str) -> list[str]:
    """A report's lines on running a paper-scale campaign with Dask (markdown)."""
    return ["Run it with Dask (each point one task, one thread; resumable as here):", "",
            "```bash",
            "# local pool (default), or any Dask scheduler:",
            f"python -m {module} --paper --out {out} \\",
            "    --scheduler tcp://scheduler:8786",
            "# on a batch system, a dask-jobqueue cluster gives that address:",
            "python -c 'from dask_jobqueue import SLURMCluster; c = SLURMCluster(cores=32, "
            f"processes=32, memory=\"64GB\", walltime=\"{walltime}\"); c.scale(jobs=4); "
            "print(c.scheduler_address); input()'",
            "```", ""]


def cli(argv: Iterable[str] | None, *, module: str, description: str,
        plans: Mapping[str, tuple[Callable[[], Any], str]],
        reanalyse: Callable[[Path, Any], int], run_campaign: Callable[..., Any],
        write_report: Callable[..., Path],
        options: Mapping[str, tuple[str, str]] | None = None) -> None:
    """The command line of a reproduction campaign: ``--quick`` (default), ``--full`` or
    ``--paper`` (``plans``: name -> (plan factory, help)), ``--out``, ``--report``,
    ``--workers`` / ``--scheduler``, ``--reanalyse``, ``--only-report``; ``options`` (name ->
    (default, help)) are further string options, passed to ``write_report`` by keyword."""
    import argparse

    ap = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    mode = ap.add_mutually_exclusive_group()
    for name, (_, text) in plans.items():
        mode.add_argument(f"--{name}", action="store_true", help=text)
    stem = module.rsplit(".", 1)[-1]
    ap.add_argument("--out", default=None, help=f"dataset directory (default results/{stem}_"
                    f"<mode>; the committed full campaign: docs/data/{stem})")
    ap.add_argument("--report", default=None, help="report file (default OUT/report.md)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address")
    ap.add_argument("--only-report", action="store_true", help="no runs, the report only")
    ap.add_argument("--reanalyse", action="store_true",
                    help="first recompute the finished points from the data kept in OUT/work")
    for name, (default, text) in (options or {}).items():
        ap.add_argument(f"--{name}", default=default, help=f"{text} (default {default})")
    a = ap.parse_args(list(argv) if argv is not None else None)
    chosen = next((n for n in plans if getattr(a, n)), "quick")
    plan = plans[chosen][0]()
    out = Path(a.out or f"results/{stem}_{plan.name}")
    if a.reanalyse:
        print(f"reanalysed: {reanalyse(out, plan)} points to go on with")
    if not a.only_report:
        run_campaign(plan, out, workers=a.workers, scheduler=a.scheduler)
    path = write_report(out, Path(a.report) if a.report else out / "report.md", plan,
                        **{k: getattr(a, k) for k in options or {}})
    print(f"report: {path}")
