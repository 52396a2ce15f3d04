"""Command line: ``granflow run SCENE.toml --out DIR``, ``granflow sweep GRID.toml --out DIR``,
``granflow summary DIR``, ``granflow plot DIR``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from granflow.errors import GranflowError


def _cmd_run(a: argparse.Namespace) -> int:
    from granflow.runner import execute, load_spec

    spec = load_spec(a.scene)
    r = execute(spec, a.out, progress=None if not a.quiet else False, threads=a.threads)
    print(f"{r.status}: {r.directory} ({r.wall_seconds:.1f} s)")
    _print_summary(r.summary)
    return 0


def _cmd_sweep(a: argparse.Namespace) -> int:
    import polars as pl

    from granflow.errors import ParameterError
    from granflow.runner import load_spec
    from granflow.study import run_grid

    spec = load_spec(a.grid)
    grid = spec.pop("grid", None)
    # (a single seed = s is a grid of one seed)
    seed = spec.pop("seed", 0)
    seeds = spec.pop("seeds", [seed])
    if not isinstance(grid, dict):
        raise ParameterError(f"invalid grid = {grid!r} in {a.grid}: allowed a [grid] table of "
                             "parameter = [values]")
    if not isinstance(seeds, list) or not all(isinstance(x, int) for x in seeds):
        raise ParameterError(f"invalid seeds = {seeds!r}: allowed a list of integers")
    df = run_grid(spec, grid, a.out, seeds=seeds, workers=a.workers, scheduler=a.scheduler,
                  threads=a.threads)
    out = Path(a.out) / "sweep.parquet"
    df.write_parquet(out)
    pl.Config.set_tbl_cols(-1)
    pl.Config.set_tbl_rows(-1)
    print(df)
    failed = df.filter(pl.col("status") == "failed")
    for row in failed.iter_rows(named=True):
        print(f"failed: {row['directory']}: {row.get('error')}", file=sys.stderr)
    print(f"{df.height} runs ({failed.height} failed); table {out}")
    return 1 if failed.height else 0


def _print_summary(s: dict) -> None:
    width = max((len(k) for k in s), default=0)
    for k in sorted(s):
        v = s[k]
        if k.endswith("_se"):
            continue
        se = s.get(k + "_se")
        if isinstance(v, float):
            txt = f"{v:.6g}" + (f" ± {se:.2g}" if isinstance(se, float) else "")
        else:
            txt = json.dumps(v) if isinstance(v, (dict, list)) else str(v)
        print(f"  {k:<{width}}  {txt}")


def _cmd_summary(a: argparse.Namespace) -> int:
    f = Path(a.dir) / "summary.json"
    if not f.exists():
        print(f"no summary.json in {a.dir} (run not finished?)", file=sys.stderr)
        return 2
    s = json.loads(f.read_text())
    m = json.loads((Path(a.dir) / "manifest.json").read_text())
    print(f"{m['spec']['scene']} run, seed {m['seed']}, status {m['status']}, "
          f"{m['steps_done']} steps, {m['wall_seconds']:.1f} s")
    _print_summary(s)
    return 0


def _cmd_plot(a: argparse.Namespace) -> int:
    from granflow.analysis.plots import plot_run

    for p in plot_run(a.dir):
        print(p)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="granflow", description="DEM granular-flow simulations")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a scene described by a TOML file",
                       description="Run (or resume) a scene into a directory of Parquet files.")
    r.add_argument("scene", help="scene TOML file (see examples/*.toml)")
    r.add_argument("--out", required=True, help="output directory")
    r.add_argument("--threads", type=int, default=None, help="threads (default: all cores)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(fn=_cmd_run)
    w = sub.add_parser("sweep", help="run a grid of a scene's parameters and seeds",
                       description="Run every combination of a TOML file's [grid] (parameter = "
                       "[values]) and its seeds = [...] over a base scene spec (the other keys, "
                       "as for 'run'), into one hive-partitioned dataset DIR/key=value/.../seed=s/;"
                       " resumable (finished runs are skipped); failed runs are recorded with "
                       "their error in DIR/sweep.parquet (exit status 1).")
    w.add_argument("grid", help="sweep TOML file: a scene spec plus [grid] and seeds")
    w.add_argument("--out", required=True, help="output directory (the dataset's root)")
    w.add_argument("--workers", type=int, default=None,
                   help="local processes (default: one per core, at most one per run)")
    w.add_argument("--scheduler", default=None,
                   help="a Dask scheduler address (tcp://host:port) to run on instead")
    w.add_argument("--threads", type=int, default=None,
                   help="threads per run (default: cores/workers)")
    w.set_defaults(fn=_cmd_sweep)
    s = sub.add_parser("summary", help="print a run's analysis with error bars",
                       description="Print the summary (means ± standard errors) of a run.")
    s.add_argument("dir")
    s.set_defaults(fn=_cmd_summary)
    p = sub.add_parser("plot", help="write a run's figures (PNG)",
                       description="Write the scene's figures as PNG files into DIR/plots.")
    p.add_argument("dir")
    p.set_defaults(fn=_cmd_plot)
    a = ap.parse_args(argv)
    try:
        return a.fn(a)
    except GranflowError as e:
        print(f"granflow: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("granflow: interrupted (checkpoint written; run again to resume)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
