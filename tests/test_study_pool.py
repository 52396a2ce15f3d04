"""study.map_tasks' pool: a parent killed outright takes its workers with it (on Linux)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import granflow
import pytest

SCRIPT = """
import os, time
from granflow.study import map_tasks

def slow(i, threads):
    os.write(1, f"worker {os.getpid()}\\n".encode())  # one write: the workers share the pipe
    time.sleep(60)

if __name__ == "__main__":
    for _ in map_tasks(slow, [(1,), (2,)], workers=2):
        pass
"""

# tasks that simulate (a run turns SIGTERM into a clean stop of the run, and the worker then
# takes the next queued task: more tasks than workers)
SIMULATING = """
import os
import granflow as gf
from granflow.study import map_tasks

def simulate(i, threads):
    box = gf.Box(length=(6.0, 6.0, 6.0))
    x, d = gf.random_packing(gf.sizes.uniform(0.9, 1.1), box, 0.3, seed=i)
    sim = gf.Simulation(x, d, box, gf.ContactLaw(kn=1e5, e_n=0.8, mu=0.5), threads=1,
                        velocities=gf.maxwell_velocities(len(d), 1.0, seed=i))
    os.write(1, f"worker {os.getpid()}\\n".encode())  # one write: the workers share the pipe
    while True:
        sim.run(200, progress=False)

if __name__ == "__main__":
    for _ in map_tasks(simulate, [(i,) for i in range(6)], workers=2):
        pass
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
@pytest.mark.parametrize("source", [SCRIPT, SIMULATING], ids=["sleeping", "simulating"])
def test_workers_end_with_a_killed_parent(tmp_path, source):
    script = tmp_path / "pool.py"
    script.write_text(source)
    # the granflow this test imports (installed, or the source tree with its extension)
    env = {**os.environ, "PYTHONPATH": str(Path(granflow.__file__).resolve().parents[1])}
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True,
                            env=env)
    assert proc.stdout is not None
    workers = [int(proc.stdout.readline().split()[1]) for _ in range(2)]
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 10
    alive = workers
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [w for w in workers if _running(w)]
    assert not alive, f"workers {alive} outlived their parent"


def _running(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.split(") ")[1][0] != "Z"


def _threads_of(i: int, threads: int) -> tuple[int, int]:
    return i, threads


def test_map_tasks_gives_each_task_the_threads_asked_for() -> None:
    from granflow.errors import ParameterError
    from granflow.study import map_tasks

    ncores = os.cpu_count() or 1
    # default: cores/workers (so two campaigns side by side each ask for threads=1)
    assert dict(map_tasks(_threads_of, [(0,)], workers=1)) == {0: (0, ncores)}
    assert dict(map_tasks(_threads_of, [(0,), (1,)], workers=1, threads=1)) \
        == {0: (0, 1), 1: (1, 1)}
    with pytest.raises(ParameterError, match="threads = 0"):
        list(map_tasks(_threads_of, [(0,)], workers=1, threads=0))
