"""A dependency-free progress bar: simulated time, particle-steps per second, time left.

Shown only when stderr is a terminal and the run is expected to take more than a few seconds.
"""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, total_steps: int, n_particles: int, dt: float, enabled: bool | None = None):
        self.total = max(int(total_steps), 1)
        self.n = n_particles
        self.dt = dt
        self.t0 = time.perf_counter()
        self.done = 0
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._last = 0.0
        self._shown = False

    def update(self, steps_done: int, sim_time: float) -> None:
        self.done = steps_done
        now = time.perf_counter()
        elapsed = now - self.t0
        if not self.enabled or elapsed < 2.0 or now - self._last < 0.25:
            return
        self._last = now
        rate = self.done / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else float("inf")
        frac = self.done / self.total
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        sys.stderr.write(
            f"\r[{bar}] {100 * frac:5.1f}%  t = {sim_time:.4g}  "
            f"{rate * self.n:.3g} particle-steps/s  ETA {left:6.1f} s "
        )
        sys.stderr.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            sys.stderr.write("\n")
            sys.stderr.flush()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0
