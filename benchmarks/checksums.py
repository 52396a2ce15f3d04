"""The bitwise checks a refactoring must keep (their values are in benchmarks/NOTES.md).

    python benchmarks/checksums.py [--state FILE] [--skip-step]

1. Step bench: ``cargo bench --bench step -- FILE 3000 T`` on the flowing channel state of
   ``benchmarks/kernel_state.py`` (6754 particles), on 1 and 2 threads and with
   ``GRANFLOW_NO_AVX2=1``; it prints ``checksum (x + v by id)``.
2. Cell: a stress-controlled cell, ``ShearCell(N=1000, seed=1, tc_reading="printed",
   start="dilute")`` prepared (the reading the checksum was first taken with; the other
   parameters at their defaults: mu = 0.3, p_ext = 1e-4, tau_ext/p_ext = 0.5), 3000 steps
   of the kernel; the checksum is sum |x| + 1e3 sum |v| + sum |w|, on 1 and 2 threads and
   with ``GRANFLOW_NO_AVX2=1``.

Each setting runs in its own process: the AVX2 switch is read once per process.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = [("1 thread", 1, False), ("2 threads", 2, False), ("1 thread, no AVX2", 1, True)]

CELL_SNIPPET = """
import numpy as np
from granflow.scenes.cell import ShearCell
c = ShearCell(N=1000, seed=1, tc_reading="printed", start="dilute", threads={threads})
c.prepare()
s = c.core
s.run(3000)
x, v, w = (np.asarray(a) for a in (s.positions(), s.velocities(), s.angular_velocities()))
print(repr(float(np.abs(x).sum() + 1e3 * np.abs(v).sum() + np.abs(w).sum())))
"""


def _env(no_avx2: bool) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("GRANFLOW_NO_AVX2", None)
    if no_avx2:
        env["GRANFLOW_NO_AVX2"] = "1"
    return env


def cell_checksums() -> dict[str, str]:
    out = {}
    for name, threads, no_avx2 in SETTINGS:
        r = subprocess.run([sys.executable, "-c", CELL_SNIPPET.format(threads=threads)],
                           env=_env(no_avx2), capture_output=True, text=True, check=True)
        out[name] = r.stdout.strip().splitlines()[-1]
    return out


def step_checksums(state: Path) -> dict[str, str]:
    if not state.exists():
        subprocess.run([sys.executable, str(ROOT / "benchmarks" / "kernel_state.py"), str(state)],
                       check=True)
    subprocess.run(["cargo", "bench", "--bench", "step", "--no-run"], cwd=ROOT, check=True,
                   capture_output=True)
    out = {}
    for name, threads, no_avx2 in SETTINGS:
        r = subprocess.run(["cargo", "bench", "--bench", "step", "--", str(state), "3000",
                            str(threads)], cwd=ROOT, env=_env(no_avx2), capture_output=True,
                           text=True, check=True)
        m = re.search(r"checksum \(x \+ v by id\) (\S+)", r.stdout + r.stderr)
        out[name] = m.group(1) if m else "(no checksum printed)"
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--state", type=Path, default=ROOT / "benchmarks" / "out" / "channel.bin",
                    help="step-bench state file (written by kernel_state.py if missing)")
    ap.add_argument("--skip-step", action="store_true", help="only the cell checksum")
    a = ap.parse_args()
    if not a.skip_step:
        a.state.parent.mkdir(exist_ok=True)
        for k, v in step_checksums(a.state).items():
            print(f"step bench, {k}: {v}")
    for k, v in cell_checksums().items():
        print(f"cell, {k}: {v}")


if __name__ == "__main__":
    main()
