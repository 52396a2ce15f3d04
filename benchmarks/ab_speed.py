"""Interleaved A/B speed of two builds of granflow on the same states (for refactorings).

    python benchmarks/ab_speed.py A_DIR B_DIR [--rounds 3] [--steps 20000] [--parts channel cell]

A_DIR and B_DIR each hold an installed ``granflow`` package (a copy of site-packages/granflow,
extension included); each measurement runs in its own process with that directory first on
``PYTHONPATH``. Per round every configuration runs A then B, the order swapped every other
round, so slow drifts of the machine (the other core busy, the VM's core placement) fall on
both alike. Reported: particle-steps/s per run, the best and median of each, and the median of
the paired ratios B/A.

- channel: the flowing channel state of ``compare_lammps.py`` (W = 20, H = 30, B = 10 d, 6754
  particles, kn = 1e6, e_n = 0.82, mu = 0.5, dt = 1.2e-4, skin 0.2), ``steps`` steps after the
  set-up evaluation, on 1 and 2 threads (the speed part of ``compare_lammps.py``);
- cell: a stress-controlled cell ``ShearCell(N=2000, seed=1)`` brought to steady shear
  (150 000 steps, untimed), then ``steps`` steps timed, on 1 and 2 threads.
Only the API both builds share is used.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

WORKER = r"""
import json, sys, time
import numpy as np
import granflow as gf
kind, threads, steps, state = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
if kind == "channel":
    z = np.load(state)
    W, H, B = float(z["W"]), float(z["H"]), float(z["B"])
    law = gf.ContactLaw(kn=1e6, e_n=0.82, mu=0.5, kt=2 / 7 * 1e6, xi_t_ratio=0.5)
    sim = gf.Simulation(z["x"], z["d"], gf.Box(length=(W, H, B), periodic=(False, True, True)),
                        law, density=1.0, velocities=z["v"], angular_velocities=z["omega"],
                        walls=[gf.Wall(0, 0.0, 1.0), gf.Wall(0, W, -1.0)], wall_law=law,
                        gravity=(0.0, -1.0, 0.0), dt=1.2e-4, skin=0.2, threads=threads)
    core = getattr(sim, "core", None) or sim._sim
    core.compute_forces()
    n = len(z["d"])
else:
    try:
        from granflow.scenes.cell import ShearCell
    except ImportError:
        from granflow.cell import ShearCell
    cell = ShearCell(N=2000, seed=1, threads=threads, start="dilute")
    cell.prepare()  # (the dilute start: builds the kernel, runs nothing)
    core = cell.core
    core.run(150_000)
    n = core.n
t0 = time.perf_counter()
core.run(steps)
print(json.dumps({"rate": n * steps / (time.perf_counter() - t0)}))
"""


def measure(pkg: Path, kind: str, threads: int, steps: int, state: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(pkg))
    r = subprocess.run([sys.executable, "-c", WORKER, kind, str(threads), str(steps), str(state)],
                       env=env, capture_output=True, text=True, check=True)
    return float(json.loads(r.stdout.strip().splitlines()[-1])["rate"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path, help="directory holding build A's granflow package")
    ap.add_argument("b", type=Path, help="directory holding build B's granflow package")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--parts", nargs="+", default=["channel", "cell"],
                    choices=["channel", "cell"])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    a = ap.parse_args()
    state = next((HERE / "out").glob("channel_W20_H30_B10_seed1_flow*.npz"), None)
    if "channel" in a.parts and state is None:
        sys.exit("no cached channel state: run benchmarks/compare_lammps.py --parts speed or "
                 "benchmarks/kernel_state.py once first")
    configs = [(k, t) for k in a.parts for t in a.threads]
    rates: dict[tuple[str, int], dict[str, list[float]]] = {c: {"A": [], "B": []} for c in configs}
    for r in range(a.rounds):
        for kind, threads in configs:
            order = ("A", "B") if r % 2 == 0 else ("B", "A")
            for lab in order:
                pkg = a.a if lab == "A" else a.b
                x = measure(pkg, kind, threads, a.steps, state or Path("-"))
                rates[(kind, threads)][lab].append(x)
                print(f"round {r + 1} {kind} {threads} thread(s) {lab}: {x:.4g}", flush=True)
    print(f"\n{'configuration':<22} {'A best':>9} {'A median':>9} {'B best':>9} {'B median':>9} "
          f"{'B/A (median of pairs)':>22}")
    rows = []
    for (kind, threads), d in rates.items():
        ratios = [b / x for x, b in zip(d["A"], d["B"], strict=True)]
        row = {"config": f"{kind}, {threads} thread(s)", "A": d["A"], "B": d["B"],
               "ratio_median": statistics.median(ratios), "ratios": ratios}
        rows.append(row)
        print(f"{row['config']:<22} {max(d['A']):>9.4g} {statistics.median(d['A']):>9.4g} "
              f"{max(d['B']):>9.4g} {statistics.median(d['B']):>9.4g} "
              f"{row['ratio_median']:>22.3f}")
    if a.out:
        a.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
