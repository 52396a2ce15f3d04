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
    ``--workers`` / ``--threads`` / ``--scheduler``, ``--reanalyse``, ``--only-report``;
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
        run_campaign(plan, out, workers=a.workers, scheduler=a.scheduler, threads=a.threads)
    path = write_report(out, Path(a.report) if a.report else out / "report.md", plan,
                        **{k: getattr(a, k) for k in options or {}})
    print(f"report: {path}")
