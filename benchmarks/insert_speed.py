"""Speed of random sphere insertion (``_core.insert_spheres``, random sequential addition).

    python benchmarks/insert_speed.py [--rounds 3] [--limit 5.0]

Diameters uniform in [0.9, 1.1] (numpy ``default_rng(1)``), a periodic cube sized for volume
fraction phi = 0.3, seed 1. Prints the best of ``rounds`` wall times and spheres/s for 1e5 (for
reference) and 1e6 spheres, and a hash of the 1e6 positions (their bits must not change).
Exit code 1 if 1e6 spheres take longer than ``limit`` seconds.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time

import numpy as np
from granflow import _core

PHI = 0.3


def case(n: int) -> tuple[np.ndarray, float]:
    d = np.random.default_rng(1).uniform(0.9, 1.1, n)
    side = float((np.pi / 6 * np.sum(d**3) / PHI) ** (1 / 3))
    return d, side


def best_time(n: int, rounds: int) -> tuple[float, str]:
    d, side = case(n)
    best, digest = float("inf"), ""
    for _ in range(rounds):
        t0 = time.perf_counter()
        x = _core.insert_spheres(d, (0.0, 0.0, 0.0), (side, side, side), (True, True, True), 1)
        best = min(best, time.perf_counter() - t0)
        digest = hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()[:16]
    return best, digest


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--limit", type=float, default=5.0, help="seconds allowed for 1e6 spheres")
    a = ap.parse_args()
    print(f"random insertion, d ~ U(0.9, 1.1), periodic cube, phi = {PHI}, best of {a.rounds}")
    t = {}
    for n in (100_000, 1_000_000):
        t[n], digest = best_time(n, a.rounds)
        print(f"  N = {n:>9,}: {t[n]:7.2f} s  {n / t[n]:12,.0f} spheres/s  positions {digest}")
    if t[1_000_000] > a.limit:
        print(f"FAIL: 1e6 spheres took {t[1_000_000]:.2f} s > {a.limit} s")
        return 1
    print(f"ok: 1e6 spheres in {t[1_000_000]:.2f} s <= {a.limit} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
