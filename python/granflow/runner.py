"""Run a scene described by a spec (the TOML file of ``granflow run``) into a directory:

    DIR/manifest.json      parameters, seed, granflow version, status, steps, wall time
    DIR/checkpoint.gfck    latest checkpoint (resumable; written atomically)
    DIR/<table>.parquet    sample tables (atomic; parameters and seed in the file metadata)
    DIR/summary.json       the scene's analysis with standard errors
    DIR/snapshots/         particle snapshots on a trigger (optional)

Running again on the same directory resumes from the checkpoint; a finished run is skipped.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from granflow import io
from granflow._core import __version__
from granflow.errors import GranflowError, ParameterError
from granflow.scenes import SCENES, check_keys, get_scene

RUN_KEYS = {"steps": 0, "chunk": 0, "checkpoint_every": 0}
OUTPUT_KEYS = {"snapshot_every": 0, "snapshot_format": "xyz", "tables": True}
TOP_KEYS = {"scene": "", "seed": 0, "threads": None, "params": {}, "run": {}, "output": {}}


@dataclass
class RunResult:
    directory: Path
    status: str
    summary: dict[str, Any]
    wall_seconds: float


def load_spec(path: str | os.PathLike) -> dict[str, Any]:
    """Read a TOML scene file."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # Python 3.10
        import tomli as tomllib
    with open(path, "rb") as f:
        return tomllib.load(f)


def validate_spec(spec: Mapping[str, Any]) -> dict[str, Any]:
    check_keys("spec", spec, TOP_KEYS)
    if "scene" not in spec:
        raise ParameterError(f"invalid spec: missing key 'scene': allowed one of {sorted(SCENES)}")
    run = dict(spec.get("run", {}))
    check_keys("run", run, RUN_KEYS)
    steps = run.get("steps")
    if not isinstance(steps, int) or steps < 0:
        raise ParameterError(f"invalid run.steps = {steps!r}: allowed an integer >= 0")
    out = dict(spec.get("output", {}))
    check_keys("output", out, OUTPUT_KEYS)
    if out.get("snapshot_format", "xyz") not in ("xyz", "vtp"):
        raise ParameterError(
            f"invalid output.snapshot_format = {out['snapshot_format']!r}: allowed 'xyz' or 'vtp'"
        )
    return {**spec, "run": run, "output": out}


def _same_run(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Two specs describe the same run if they differ at most in run.steps (so a run can be
    extended: ``granflow run`` with more steps resumes from the checkpoint)."""
    def strip(s: Mapping[str, Any]) -> Any:
        c = json.loads(json.dumps(s))
        c.get("run", {}).pop("steps", None)
        return c

    return strip(a) == strip(b)


def _read_manifest(d: Path) -> dict[str, Any] | None:
    f = d / "manifest.json"
    if not f.exists():
        return None
    return json.loads(f.read_text())


def _load_tables(d: Path, upto_time: float) -> dict[str, pa.Table]:
    """Tables written with the last checkpoint, without rows newer than it."""
    out: dict[str, pa.Table] = {}
    for f in d.glob("*.parquet"):
        if f.stem.startswith("errors"):
            continue
        t = pq.read_table(f)
        tcol = "t1" if "t1" in t.column_names else ("t" if "t" in t.column_names else None)
        if tcol is not None:
            t = t.filter(pc.less_equal(t[tcol], upto_time * (1 + 1e-12) + 1e-300))
        out[f.stem] = t.replace_schema_metadata(None)
    return out


def execute(
    spec: Mapping[str, Any],
    out: str | os.PathLike,
    progress: bool | None = None,
    threads: int | None = None,
) -> RunResult:
    """Run (or resume, or skip if finished) the scene of ``spec`` into directory ``out``."""
    spec = validate_spec(spec)
    d = Path(out)
    d.mkdir(parents=True, exist_ok=True)
    man = _read_manifest(d)
    if (man and man.get("status") == "finished" and _same_run(man["spec"], spec)
            and man.get("steps_done", 0) >= int(spec["run"]["steps"])):
        summ = json.loads((d / "summary.json").read_text()) if (d / "summary.json").exists() else {}
        return RunResult(d, "skipped", summ, man.get("wall_seconds", 0.0))
    cls = get_scene(spec["scene"])
    seed = int(spec.get("seed", 0))
    threads = threads if threads is not None else spec.get("threads")
    scene = cls.from_spec(spec.get("params", {}), seed=seed, threads=threads)
    ck = d / "checkpoint.gfck"
    wall0 = 0.0
    if ck.exists() and man is not None and _same_run(man["spec"], spec):
        scene.restore(ck)
        scene.load_tables(_load_tables(d, scene.core.time))
        wall0 = float(man.get("wall_seconds", 0.0))
        step0 = int(man.get("step0", 0))
    else:
        scene.prepare(progress=progress)
        step0 = scene.core.step  # (a preparation that steps the kernel, as the cell's compaction)
    core = scene.core
    run, outp = spec["run"], spec["output"]
    steps = int(run["steps"])
    total = step0 + steps
    every = int(run.get("checkpoint_every", 0)) or max(steps // 10, 1)
    snap_every = int(outp.get("snapshot_every", 0))
    params = {"scene": spec["scene"], "seed": seed, **scene.parameters()}
    manifest: dict[str, Any] = {
        "spec": spec,
        "parameters": params,
        "granflow_version": __version__,
        "seed": seed,
        "status": "running",
        "step0": step0,
        "steps_done": core.step - step0,
        "steps_total": steps,
        "wall_seconds": wall0,
    }
    io.write_manifest(d, manifest)
    t0 = time.perf_counter()

    def save_all(status: str) -> None:
        if outp.get("tables", True):
            for name, t in scene.tables().items():
                io.write_parquet(t, d / f"{name}.parquet", params=params, seed=seed)
        scene.save_checkpoint(ck)
        manifest.update(
            status=status,
            steps_done=core.step - step0,
            wall_seconds=wall0 + time.perf_counter() - t0,
        )
        io.write_manifest(d, manifest)

    try:
        while core.step < total:
            nxt = min(total, (core.step // every + 1) * every)
            if snap_every:
                nxt = min(nxt, (core.step // snap_every + 1) * snap_every)
            scene.run(nxt - core.step, progress=progress)
            if snap_every and core.step % snap_every == 0:
                fmt = outp.get("snapshot_format", "xyz")
                io.snapshot(scene, d / "snapshots" / f"snap_{core.step:010d}.{fmt}")
            if core.step % every == 0 and core.step < total:
                save_all("running")
    except (KeyboardInterrupt, SystemExit):
        save_all("interrupted")
        raise
    except GranflowError:
        # an unstable run stops with a clear error; what it recorded stays readable
        if outp.get("tables", True):
            for name, t in scene.tables().items():
                io.write_parquet(t, d / f"{name}.parquet", params=params, seed=seed)
        manifest.update(status="failed", steps_done=core.step - step0,
                        wall_seconds=wall0 + time.perf_counter() - t0)
        io.write_manifest(d, manifest)
        raise
    summary = scene.summary()
    summary["wall_seconds"] = wall0 + time.perf_counter() - t0
    summary["steps"] = core.step
    with io.atomic_path(d / "summary.json") as tmp:
        tmp.write_text(json.dumps(io._jsonable(summary), indent=1, sort_keys=True))
    save_all("finished")
    if cls.error_report:
        # statistical error against run time, beside the results (errors.parquet, errors.txt)
        try:
            from granflow.analysis.report import error_report_for_run

            rep = error_report_for_run(d)
            with io.atomic_path(d / "errors.txt") as tmp:
                tmp.write_text(rep.text() + "\n")
        except Exception as exc:  # too little data for block analysis: say so, keep the run
            with io.atomic_path(d / "errors.txt") as tmp:
                tmp.write_text(f"error report not available: {type(exc).__name__}: {exc}\n")
    return RunResult(d, "finished", summary, manifest["wall_seconds"])
