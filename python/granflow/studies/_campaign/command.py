"""The command line of a campaign study (:func:`cli`)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any


def cli(argv: Iterable[str] | None, *, module: str, description: str,
        plans: Mapping[str, tuple[Callable[[], Any], str]],
        reanalyse: Callable[[Path, Any], int], run_campaign: Callable[..., Any],
        write_report: Callable[..., Path],
        options: Mapping[str, tuple[str, str]] | None = None) -> None:
    """The command line of a reproduction campaign: ``--quick`` (default), ``--full`` or
    ``--paper`` (``plans``: name -> (plan factory, help)), ``--out``, ``--report``,
    ``--workers`` / ``--threads`` / ``--scheduler``, ``--reanalyse``, ``--only-report``,
    ``--status`` (:func:`print_status`);
    ``options`` (name -> (default, help)) are further string options, passed to
    ``write_report`` by keyword."""
    import argparse

    ap = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    mode = ap.add_mutually_exclusive_group()
    for name, (_, text) in plans.items():
        mode.add_argument(f"--{name}", action="store_true", help=text)
    stem = module.rsplit(".", 1)[-1]
    ap.add_argument("--out", default=None, help=f"dataset directory (default results/{stem}_"
                    f"<mode>; the committed full campaign: docs/data/{stem})")
    ap.add_argument("--report", default=None, help="report file (default OUT/report.md)")
    ap.add_argument("--workers", type=int, default=None,
                    help="local processes (default: one per core)")
    ap.add_argument("--threads", type=int, default=None,
                    help="threads per point (default: cores/workers; 1 where another campaign "
                    "shares the cores)")
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address")
    ap.add_argument("--only-report", action="store_true", help="no runs, the report only")
    ap.add_argument("--status", action="store_true",
                    help="no runs, no report: where each started, unfinished point stands")
    ap.add_argument("--select", default=None, metavar="REGEX",
                    help="run only the plan's points whose key matches (re.search), e.g. "
                    "'_I0.001_s1$'; the report still covers the whole dataset")
    ap.add_argument("--reanalyse", action="store_true",
                    help="first recompute the finished points from the data kept in OUT/work")
    for name, (default, text) in (options or {}).items():
        ap.add_argument(f"--{name}", default=default,
                        help=f"{text} (default {default})" if default else text)
    a = ap.parse_args(list(argv) if argv is not None else None)
    chosen = next((n for n in plans if getattr(a, n)), "quick")
    whole = plans[chosen][0]()
    plan = whole
    if a.select is not None:
        from granflow.errors import ParameterError

        try:
            plan = select(whole, a.select)
        except ParameterError as e:
            ap.error(str(e))
    out = Path(a.out or f"results/{stem}_{plan.name}")
    if a.status:
        print_status(out, plan)
        return
    if a.reanalyse:
        print(f"reanalysed: {reanalyse(out, plan)} points to go on with")
    if not a.only_report:
        run_campaign(plan, out, workers=a.workers, scheduler=a.scheduler, threads=a.threads,
                     whole=whole)
    from .engine import dataset_lock

    # (the report is of the whole plan: what is left of it, its cost, whatever was selected;
    # it reads the tables whole, so not while a process beside this one appends a row)
    with dataset_lock(out):
        path = write_report(out, Path(a.report) if a.report else out / "report.md", whole,
                            **{k: getattr(a, k) for k in options or {}})
    print(f"report: {path}")


def print_status(out: Path, plan: Any) -> None:
    """The ``--status`` table (:func:`.engine.status`): a line per started, unfinished point,
    and the count of points with a row."""
    import polars as pl

    from .engine import done_keys, plan_points, status

    tab = status(out, plan)
    points = plan_points(plan)
    done = done_keys(out, type(points[0])) & {p.key for p in points} if points else set()
    # (a row from before a study's present stop rule counts here, though a run goes on with it)
    print(f"{plan.name} in {out}: {len({p.key for p in points})} points, {len(done)} with a "
          f"row in points.parquet, {tab.height} started")
    if tab.height:
        with pl.Config(tbl_rows=-1, tbl_hide_dataframe_shape=True, tbl_hide_column_data_types=True,
                       fmt_str_lengths=80, tbl_width_chars=200):
            print(tab.with_columns(pl.col("t_run", "wall_seconds", "cpu_seconds").round(0)))


def select(plan: Any, pattern: str) -> Any:
    """``plan`` with only the points whose ``key`` matches ``pattern`` (re.search) in each of
    its tuples of points (a cell plan's ``points``; reproduce_000's ``points``, ``branches``
    and ``later``): a piece of a campaign run into the same dataset, with the plan's settings
    unchanged. Raises ParameterError if the pattern is not a regular expression or matches
    no point."""
    import dataclasses
    import re

    from granflow.errors import ParameterError

    from .engine import point_fields

    try:
        rx = re.compile(pattern)
    except re.error as e:
        raise ParameterError(f"invalid select = {pattern!r}: allowed a regular expression "
                             f"({e})") from None
    kept = {name: tuple(p for p in v if rx.search(p.key))
            for name, v in point_fields(plan).items()}
    if not any(kept.values()):
        raise ParameterError(f"invalid select = {pattern!r}: allowed a pattern matching at "
                             f"least one point key of the {plan.name} plan (e.g. "
                             f"{next(iter(plan.points)).key!r})")
    return dataclasses.replace(plan, **kept)
