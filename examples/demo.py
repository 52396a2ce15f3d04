"""granflow demo: a small periodic granular gas, end to end (build, run, tables, Parquet,
summary). Run with `bash scripts/demo.sh`."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import polars as pl
from granflow.runner import execute

SPEC = {
    "scene": "gas",
    "seed": 1,
    "params": {"L": 10.0, "phi": 0.3, "kn": 1e5, "e_n": 0.8, "mu": 0.5, "sample_every": 100},
    "run": {"steps": 5000, "checkpoint_every": 2500},
    "output": {"snapshot_every": 2500, "snapshot_format": "xyz"},
}


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="granflow-"))
    r = execute(SPEC, out / "gas")
    print(f"run {r.status} in {r.wall_seconds:.1f} s -> {r.directory}")
    series = pl.read_parquet(r.directory / "series.parquet")
    print(series.tail(3))
    print("summary:", r.summary)


if __name__ == "__main__":
    main()
