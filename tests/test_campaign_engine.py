"""The campaign engine (granflow.studies._campaign.engine) on a scripted scene, in seconds: the
stint loop, its one stop rule (run and reanalyse alike), resuming, and errors by type."""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import polars as pl
import pyarrow as pa
import pytest
from granflow.errors import DilationError, GranflowError, InstabilityError, ParameterError
from granflow.studies._campaign import Study, reanalyse, run_point, run_points
from granflow.studies._campaign.engine import fmt, is_current


@dataclass(frozen=True)
class Point:
    name: str
    #: stints after which the scripted flow arrests (0: never)
    arrest_at: int = 0
    #: stint during which the scene raises ``raises`` (0: never)
    fail_at: int = 0
    raises: str = ""

    @property
    def key(self) -> str:
        return self.name


@dataclass(frozen=True)
class Plan:
    stint: float = 1.0  # time units
    t_max: float = 10.0
    dt: float = 0.25


ERRORS = {"dilation": DilationError, "instability": InstabilityError,
          "parameter": ParameterError}


class Scene:
    """A scripted scene: a sample per step of its time; stint ``fail_at`` raises ``raises``."""

    def __init__(self, point: Point, plan: Plan) -> None:
        self.point, self.plan = point, plan
        self.t: list[float] = []
        self.time, self.prepared, self.stints = 0.0, False, 0

    def prepare(self, progress: bool | None = None) -> None:
        self.prepared = True

    def run(self, steps: int, progress: bool | None = None) -> None:
        self.stints += 1
        for _ in range(steps):
            self.time += self.plan.dt
            self.t.append(self.time)
            if self.stints == self.point.fail_at and len(self.t) % 4 == 2:
                raise ERRORS[self.point.raises]("scripted")

    def tables(self) -> dict[str, pa.Table]:
        return {"series": pa.table({"t": pa.array(self.t, pa.float64())})}

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        self.t = tables["series"].column("t").to_pylist()

    def save_checkpoint(self, path: Path) -> None:
        Path(path).write_text(json.dumps({"time": self.time, "stints": self.stints}))

    def restore(self, path: Path) -> None:
        d = json.loads(Path(path).read_text())
        self.time, self.stints, self.prepared = d["time"], d["stints"], True


class Scripted(Study):
    tables = {"sample_rows": "samples"}

    def scene(self, point: Point, plan: Plan, threads: int) -> Scene:
        return Scene(point, plan)

    def next_steps(self, scene: Scene, point: Point, plan: Plan) -> int:
        left = round((plan.t_max - scene.time) / plan.dt)
        return min(round(plan.stint / plan.dt), left) if left > 0 else 0

    def progress(self, scene: Scene, prep_seconds: float) -> dict[str, Any]:
        return {"t_run": scene.time, "stints": scene.stints}

    def row(self, point: Point, plan: Plan, tables: Mapping[str, pa.Table],
            context: Mapping[str, Any]) -> dict[str, Any]:
        t = tables["series"].column("t").to_pylist()
        stints = round(len(t) * plan.dt / plan.stint)
        arrested = 0 < point.arrest_at <= stints
        return {**asdict(point), "state": "arrested" if arrested else "flowing",
                "converged": False, "samples": len(t),
                "sample_rows": [{"name": point.name, "t": x} for x in t[-2:]]}

    def stop(self, row: Mapping[str, Any], point: Point, plan: Plan,
             history: Sequence[str]) -> str | None:
        if row["state"] == "arrested" and history[-1:] == ["arrested"]:
            return "arrested"
        return "budget" if row["t_run"] >= plan.t_max - 1e-9 else None


POINTS = (Point("runs_out"), Point("arrests", arrest_at=3),
          Point("dilates", fail_at=2, raises="dilation"),
          Point("unstable", fail_at=3, raises="instability"),
          Point("bad", fail_at=1, raises="parameter"))


@pytest.fixture()
def campaign(tmp_path: Path) -> tuple[Path, pl.DataFrame]:
    d = run_points(Scripted(), POINTS, Plan(), tmp_path, workers=1, log=lambda *_: None)
    return tmp_path, d


def test_the_loop_stops_by_the_rule_and_classifies_errors_by_type(campaign):
    out, d = campaign
    rows = {r["name"]: r for r in d.iter_rows(named=True)}
    assert rows["runs_out"]["state"] == "flowing" and rows["runs_out"]["t_run"] == 10.0
    # arrested from the third stint on: stopped at the second stint running (the fourth)
    assert rows["arrests"]["state"] == "arrested" and rows["arrests"]["stints"] == 4
    assert rows["dilates"]["state"] == "runaway"  # by the exception's type, not its words
    assert rows["dilates"]["error"] == "DilationError: scripted"
    assert rows["unstable"]["state"] == "failed" and rows["bad"]["state"] == "failed"
    assert rows["unstable"]["error"].startswith("InstabilityError")
    assert rows["runs_out"]["error"] is None and not any(rows[k]["converged"] for k in rows)
    assert all(r["wall_seconds"] > 0 for r in rows.values())
    # (CPU time of the point's process, all its threads: polars' pool may add to one thread)
    assert all(0 < r["cpu_seconds"] < math.inf for r in rows.values())
    # the rows of further tables: none from a point that ended with an error
    s = pl.read_parquet(out / "samples.parquet")
    assert set(s["name"].to_list()) == {"runs_out", "arrests"}
    meta = json.loads((out / "work" / "arrests" / "meta.json").read_text())
    assert meta["history"] == ["flowing", "flowing", "arrested", "arrested"]


def test_a_finished_point_is_not_run_again_and_an_unfinished_one_goes_on(campaign):
    out, d = campaign
    said: list[str] = []
    run_points(Scripted(), POINTS, Plan(), out, workers=1, log=said.append)
    assert said == [f"campaign: {len(POINTS)} points, {len(POINTS)} done, 0 to run"]
    # a longer budget: the point goes on from its checkpoint (4 more stints)
    row = run_point(Scripted(), POINTS[0], Plan(t_max=14.0), str(out / "work"))
    assert row["t_run"] == 14.0 and row["stints"] == 14 and row["samples"] == 56
    first = d.filter(pl.col("name") == "runs_out").row(0, named=True)
    assert row["cpu_seconds"] > first["cpu_seconds"]  # (the resumed part adds to it)
    # a work directory from before cpu_seconds: unknown, not the resumed part alone
    meta = out / "work" / POINTS[0].key / "meta.json"
    kept = json.loads(meta.read_text())
    del kept["cpu_seconds"]
    meta.write_text(json.dumps(kept))
    row = run_point(Scripted(), POINTS[0], Plan(t_max=15.0), str(out / "work"))
    assert math.isnan(row["cpu_seconds"]) and row["wall_seconds"] > first["wall_seconds"]


def test_an_unfinished_point_goes_on_from_its_committed_copy_when_its_work_dir_is_lost(
        tmp_path: Path):
    point, work = Point("moved"), tmp_path / "work"
    whole = run_point(Scripted(), point, Plan(), str(tmp_path / "whole" / "work"))
    run_point(Scripted(), point, Plan(t_max=6.0), str(work))  # (a session ends at t = 6)
    kept = tmp_path / "progress" / point.key
    assert {f.name for f in kept.iterdir()} == {"checkpoint.gfck.zst", "pack.json",
                                                "meta.json", "series.parquet"}
    shutil.rmtree(work)  # (the next session starts on a new machine)
    row = run_point(Scripted(), point, Plan(), str(work))
    assert row["t_run"] == 10.0 and row["stints"] == 10
    assert {k: row[k] for k in ("samples", "sample_rows", "state")} == \
        {k: whole[k] for k in ("samples", "sample_rows", "state")}
    assert json.loads((work / point.key / "meta.json").read_text())["history"] == \
        ["flowing"] * 10
    # once the campaign writes its row, the copy goes
    run_points(Scripted(), [point], Plan(), tmp_path, workers=1, log=lambda *_: None)
    assert not kept.exists() and (tmp_path / "points.parquet").exists()


def test_a_point_says_where_it_stands_after_every_stint(tmp_path: Path, capsys):
    run_point(Scripted(), Point("slow", arrest_at=3), Plan(), str(tmp_path / "work"))
    lines = capsys.readouterr().out.splitlines()
    assert [x.split(":")[0] for x in lines] == [f"  slow stint {i}" for i in (1, 2, 3, 4)]
    assert lines[0].endswith(": flowing") and lines[-1].endswith(": arrested; done (arrested)")
    # (its meta.json keeps the study's progress fields, for --status)
    meta = json.loads((tmp_path / "work" / "slow" / "meta.json").read_text())
    assert meta["progress"] == {"t_run": 4.0, "stints": 4}


def test_a_progress_line_shows_a_dash_for_a_value_not_yet_measured():
    row = {"u": 1.23456, "early": math.nan, "n": 7}
    assert fmt(row, "u") == "1.235" and fmt(row, "n", "d") == "7"
    assert fmt(row, "early") == "-" and fmt(row, "absent") == "-"


@dataclass(frozen=True)
class Plans(Plan):
    points: tuple[Point, ...] = ()
    name: str = "toy"


def test_the_status_lists_the_started_unfinished_points_with_their_progress(
        tmp_path: Path, capsys):
    from granflow.studies._campaign.command import print_status
    from granflow.studies._campaign.engine import status

    plan = Plans(points=(Point("done"), Point("going"), Point("moved"), Point("waiting")))
    run_points(Scripted(), plan.points[:1], plan, tmp_path, workers=1, log=lambda *_: None)
    run_point(Scripted(), plan.points[1], Plans(t_max=3.0), str(tmp_path / "work"))
    run_point(Scripted(), plan.points[2], Plans(t_max=5.0), str(tmp_path / "work"))
    shutil.rmtree(tmp_path / "work" / "moved")  # (its copy is all that is left)
    tab = status(tmp_path, plan)
    assert tab.select("key", "where", "stints", "state", "t_run").rows() == [
        ("going", "work", 3, "flowing", 3.0), ("moved", "progress", 5, "flowing", 5.0)]
    assert (tab["wall_seconds"] > 0).all() and (tab["cpu_seconds"] > 0).all()
    capsys.readouterr()
    print_status(tmp_path, plan)
    out = capsys.readouterr().out
    assert out.startswith(f"toy in {tmp_path}: 4 points, 1 with a row in points.parquet, "
                          "2 started\n")
    assert "going" in out and "moved" in out and "waiting" not in out


class Branching(Scripted):
    """The point "child" starts from the final state of "parent"."""

    def start(self, scene: Scene, point: Point, plan: Plan, work: Path) -> None:
        if point.name == "child":
            scene.restore(work / "parent" / "checkpoint.gfck")
        else:
            scene.prepare()

    def starts_from(self, point: Point) -> tuple[str, ...]:
        return ("parent",) if point.name == "child" else ()

    def dependents(self, key: str, plan: Plan) -> tuple[str, ...]:
        return ("child",) if key == "parent" else ()


def test_a_branch_starts_from_its_parents_kept_copy_which_stays_until_the_branch_is_done(
        tmp_path: Path):
    quiet = {"workers": 1, "log": lambda *_: None}
    run_points(Branching(), [Point("parent")], Plan(t_max=4.0), tmp_path, **quiet)
    kept = tmp_path / "progress" / "parent"
    assert (kept / "pack.json").exists()  # (a branch needs it)
    # (its tables are not: the finished parent's copy keeps the checkpoint alone)
    assert sorted(f.name for f in kept.iterdir()) == ["checkpoint.gfck.zst", "meta.json",
                                                      "pack.json"]
    shutil.rmtree(tmp_path / "work")  # (the branch runs on a new machine)
    # (a reanalysis there keeps the parent's row: its restored work directory has no tables)
    from granflow.studies._campaign.progress import restore

    restore(kept, tmp_path / "work" / "parent")
    before = pl.read_parquet(tmp_path / "points.parquet")
    assert reanalyse(Branching(), Point, Plan(t_max=4.0), tmp_path) == 0
    assert pl.read_parquet(tmp_path / "points.parquet").equals(before)
    d = run_points(Branching(), [Point("child")], Plan(t_max=6.0), tmp_path, **quiet)
    child = d.filter(pl.col("name") == "child").row(0, named=True)
    assert child["stints"] == 6 and child["t_run"] == 6.0  # (4 of the parent's, 2 of its own)
    assert not list((tmp_path / "progress").iterdir())


class BranchingInPlan(Branching):
    """As Branching, but "child" depends on "parent" only where the plan holds it."""

    def dependents(self, key: str, plan: Plans) -> tuple[str, ...]:
        return tuple(p.name for p in plan.points if key == "parent" and p.name == "child")


def test_a_selected_piece_keeps_the_copies_that_the_whole_plan_starts_from(tmp_path: Path):
    from granflow.studies._campaign.command import select

    quiet = {"workers": 1, "log": lambda *_: None}
    whole = Plans(points=(Point("parent"), Point("child")), t_max=4.0)
    part = select(whole, "^parent$")
    assert part.points == (Point("parent"),)
    run_points(BranchingInPlan(), part.points, part, tmp_path / "a", whole=whole, **quiet)
    assert (tmp_path / "a" / "progress" / "parent" / "pack.json").exists()
    # (the piece alone, as the engine saw it before: no point of it starts from the parent)
    alone = Plans(points=(Point("parent"),), t_max=4.0)
    run_points(BranchingInPlan(), alone.points, alone, tmp_path / "b", **quiet)
    assert not (tmp_path / "b" / "progress" / "parent").exists()
    # (run as a piece of the whole plan, the copy comes back from the work directory)
    run_points(BranchingInPlan(), part.points, part, tmp_path / "b", whole=whole, **quiet)
    assert sorted(f.name for f in (tmp_path / "b" / "progress" / "parent").iterdir()) == [
        "checkpoint.gfck.zst", "meta.json", "pack.json"]


def test_a_work_directory_behind_the_committed_copy_is_not_run_on(tmp_path: Path,
                                                                 monkeypatch):
    point, work = Point("back"), tmp_path / "work"
    run_point(Scripted(), point, Plan(t_max=4.0), str(work))
    stale = tmp_path / "stale"
    shutil.copytree(work / point.key, stale)  # (the machine of an earlier session)
    run_point(Scripted(), point, Plan(t_max=7.0), str(work))  # (a later one, elsewhere)
    shutil.rmtree(work / point.key)
    shutil.copytree(stale, work / point.key)  # (back on the first machine)
    ran: list[int] = []
    run = Scene.run
    monkeypatch.setattr(Scene, "run", lambda self, n, progress=None: (ran.append(n),
                                                                      run(self, n))[1])
    row = run_point(Scripted(), point, Plan(), str(work))
    assert len(ran) == 3  # (from the copy's 7 stints, not the stale 4)
    assert row["stints"] == 10 and row["samples"] == 40
    assert len(json.loads((work / point.key / "meta.json").read_text())["history"]) == 10


def test_a_kept_copy_that_does_not_match_its_checksum_is_refused(tmp_path: Path):
    point, work = Point("torn"), tmp_path / "work"
    run_point(Scripted(), point, Plan(t_max=3.0), str(work))
    pack = tmp_path / "progress" / point.key / "pack.json"
    pack.write_text(json.dumps({**json.loads(pack.read_text()), "sha256": "0" * 64}))
    shutil.rmtree(work)
    with pytest.raises(GranflowError, match="does not match its SHA-256"):
        run_point(Scripted(), point, Plan(), str(work))
    assert not (work / point.key / "checkpoint.gfck").exists()


def test_reanalyse_calls_the_same_stop_rule(campaign):
    out, d = campaign
    assert reanalyse(Scripted(), Point, Plan(), out) == 0
    again = pl.read_parquet(out / "points.parquet")
    assert again.equals(d)
    assert pl.read_parquet(out / "samples.parquet").height == 4
    # with a longer budget the point that ran out is not done: dropped, to go on; the
    # arrested point stays arrested (its two stints running, from the kept history)
    assert reanalyse(Scripted(), Point, Plan(t_max=20.0), out) == 1
    names = pl.read_parquet(out / "points.parquet")["name"].to_list()
    assert "runs_out" not in names and "arrests" in names


def test_reanalyse_that_drops_every_point_leaves_none_done(tmp_path: Path):
    run_points(Scripted(), POINTS[:1], Plan(), tmp_path, workers=1, log=lambda *_: None)
    assert (tmp_path / "samples.parquet").exists()
    assert reanalyse(Scripted(), Point, Plan(t_max=20.0), tmp_path) == 1
    assert not (tmp_path / "points.parquet").exists()
    assert not (tmp_path / "samples.parquet").exists()
    # and the next run goes on with it, from its checkpoint, to the new budget
    d = run_points(Scripted(), POINTS[:1], Plan(t_max=20.0), tmp_path, workers=1,
                   log=lambda *_: None)
    assert d["t_run"].to_list() == [20.0]


class Ruled(Scripted):
    """Scripted, with rows written before its stop rule (no ``rule`` field) not done."""

    def row(self, point: Point, plan: Plan, tables: Mapping[str, pa.Table],
            context: Mapping[str, Any]) -> dict[str, Any]:
        return {**super().row(point, plan, tables, context), "rule": 1}

    def current(self, row: Mapping[str, Any]) -> bool:
        return row.get("rule") is not None


def test_a_row_from_before_the_stop_rule_is_run_again_and_replaced(tmp_path: Path):
    pts = POINTS[:2]
    run_points(Scripted(), pts, Plan(), tmp_path, workers=1, log=lambda *_: None)
    assert pl.read_parquet(tmp_path / "samples.parquet").height == 4
    # the work directories of the old rows are gone (another machine): runs start afresh
    for p in pts:
        for f in (tmp_path / "work" / p.key).iterdir():
            f.unlink()
    said: list[str] = []
    d = run_points(Ruled(), pts, Plan(), tmp_path, workers=1, log=said.append)
    assert said[0] == ("campaign: 2 points, 0 done, 2 to run (2 of them again: rows from "
                       "before the present stop rule)")
    # one row per point, the new one, in every table
    assert d.height == 2 and d["rule"].to_list() == [1, 1]
    s = pl.read_parquet(tmp_path / "samples.parquet")
    assert s.height == 4 and sorted(set(s["name"].to_list())) == ["arrests", "runs_out"]
    said.clear()
    run_points(Ruled(), pts, Plan(), tmp_path, workers=1, log=said.append)
    assert said == ["campaign: 2 points, 2 done, 0 to run"]


def test_the_cell_campaign_counts_only_rows_its_stop_rule_judged():
    from granflow.studies._campaign.cell import STUDY

    assert STUDY.current({"state": "flowing", "tau_max": 12.0})
    assert STUDY.current({"state": "runaway", "tau_max": math.nan})  # judged, no tau
    # an error row has no tau_max at all: done (the engine's rule for every study), not run
    # again at every start
    assert is_current(STUDY, {"state": "runaway", "tau_max": None})
    assert is_current(STUDY, {"state": "failed"})
    assert not is_current(STUDY, {"state": "flowing"})
    assert not STUDY.current({"state": "flowing", "tau_max": None})  # before the rule
    assert not STUDY.current({"state": "flowing"})


def test_cost_counts_cpu_time_where_recorded_and_wall_time_where_not():
    from granflow.studies._campaign import cost

    # a: shared its core (wall twice its CPU time); b: before cpu_seconds (null); c: NaN
    pts = pl.DataFrame({"g": ["x", "x", "y"], "n": [100, 100, 200], "steps": [10, 20, 5],
                        "wall_seconds": [20.0, 4.0, 3.0], "cpu_seconds": [10.0, None, math.nan],
                        "prep": [2.0, 0.0, math.nan]})
    per, rate = cost(pts, ["g"], "n", "steps")
    assert per["core-hours"].to_list() == pytest.approx([14.0 / 3600, 3.0 / 3600])
    assert per["longest point (s)"].to_list() == [20.0, 3.0]
    assert rate == pytest.approx((1000 + 2000 + 1000) / 17.0)
    # the preparation's share of a point's wall time comes off its core time
    _, run_rate = cost(pts, ["g"], "n", "steps", prep="prep")
    assert run_rate == pytest.approx(4000 / (10.0 * 0.9 + 4.0 + 3.0))
    # a dataset from before cpu_seconds: wall time throughout
    per, _ = cost(pts.drop("cpu_seconds"), ["g"], "n", "steps")
    assert per["core-hours"].to_list() == pytest.approx([24.0 / 3600, 3.0 / 3600])


def test_the_cell_reports_runs_left_count_rows_from_before_the_rule_as_to_run():
    from pathlib import Path

    from granflow.studies import reproduce_002 as r2
    from granflow.studies.reproduce_002_report import _remaining

    d = Path(__file__).resolve().parents[1] / "docs" / "data" / "reproduce_002"
    points = pl.read_parquet(d / "points.parquet")
    plan = r2.full_plan()

    def left(pts: pl.DataFrame) -> int:
        lines = _remaining(pts, plan, 2e7)
        return int(lines[0].split("Not yet run: ")[1].split(" points")[0]) if lines else 0

    n = left(points)
    assert n == len(plan.points) - points.height
    # a finished row without tau_max predates the stop rule: the campaign runs it again
    old = points.with_columns(pl.when(pl.int_range(pl.len()) < 3).then(None)
                              .otherwise(pl.col("tau_max")).alias("tau_max"))
    assert left(old) == n + 3


class Snapshot(Scripted):
    """Scripted, with a table measured once on the last state (Study.final)."""

    tables = {"sample_rows": "samples", "final_rows": "snapshots"}
    final_tables = ("final_rows",)

    def final(self, point: Point, scene: Scene) -> dict[str, list[dict[str, Any]]]:
        return {"final_rows": [{"name": point.name, "time": scene.time,
                                "stints": scene.stints}]}


def test_final_rows_come_from_the_last_state_once(tmp_path: Path):
    d = run_points(Snapshot(), POINTS, Plan(), tmp_path, workers=1, log=lambda *_: None)
    snap = pl.read_parquet(tmp_path / "snapshots.parquet")
    # one row per point that ended without an error, from its last state
    assert sorted(snap["name"].to_list()) == ["arrests", "runs_out"]
    by = {r["name"]: r for r in snap.iter_rows(named=True)}
    assert by["runs_out"]["time"] == 10.0 and by["arrests"]["stints"] == 4
    assert "final_rows" not in d.columns


def test_finished_points_gain_final_rows_from_their_checkpoints(tmp_path: Path):
    from granflow.studies._campaign import add_final_rows

    run_points(Scripted(), POINTS, Plan(), tmp_path, workers=1, log=lambda *_: None)
    assert not (tmp_path / "snapshots.parquet").exists()
    # the points finished before the study measured its snapshot: measured from their
    # checkpoints, once; a point without its checkpoint (another machine) stays without
    (tmp_path / "work" / "arrests" / "checkpoint.gfck").unlink()
    assert add_final_rows(Snapshot(), Point, Plan(), tmp_path) == 1
    snap = pl.read_parquet(tmp_path / "snapshots.parquet")
    assert snap.select("name", "time").rows() == [("runs_out", 10.0)]
    assert add_final_rows(Snapshot(), Point, Plan(), tmp_path) == 0


def test_reanalyse_keeps_the_rows_it_does_not_recompute(tmp_path: Path):
    run_points(Snapshot(), POINTS, Plan(), tmp_path, workers=1, log=lambda *_: None)
    before = pl.read_parquet(tmp_path / "snapshots.parquet").sort("name")
    samples = pl.read_parquet(tmp_path / "samples.parquet").sort("name", "t")
    # a point whose work directory is gone is kept as it is, with its rows of every table
    for f in (tmp_path / "work" / "arrests").iterdir():
        f.unlink()
    assert reanalyse(Snapshot(), Point, Plan(), tmp_path) == 0
    assert pl.read_parquet(tmp_path / "snapshots.parquet").sort("name").equals(before)
    assert pl.read_parquet(tmp_path / "samples.parquet").sort("name", "t").equals(samples)


def _append_one(out: str, name: str) -> None:
    from granflow.studies._campaign.engine import append_point

    append_point(Path(out), Point, {"name": name, "state": "flowing"},
                 {"samples": [{"name": name, "t": 1.0}]})


def test_a_second_process_appends_only_once_the_first_releases_the_dataset(tmp_path: Path):
    # (one process per point into one OUT is the documented way to run points side by side;
    # an append reads the table and writes it whole, so the dataset is held meanwhile)
    import multiprocessing as mp
    import time

    from granflow.studies._campaign.engine import dataset_lock

    _append_one(str(tmp_path), "first")
    ctx = mp.get_context("spawn")
    with dataset_lock(tmp_path):
        child = ctx.Process(target=_append_one, args=(str(tmp_path), "second"))
        child.start()
        time.sleep(3.0)  # (time for the child to start and reach the lock)
        assert child.is_alive(), "the child wrote while the dataset was held"
        assert pl.read_parquet(tmp_path / "points.parquet")["name"].to_list() == ["first"]
    child.join(60)
    assert child.exitcode == 0
    for stem in ("points", "samples"):
        assert pl.read_parquet(tmp_path / f"{stem}.parquet")["name"].to_list() == [
            "first", "second"]


def test_many_appends_from_two_processes_lose_no_row(tmp_path: Path):
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    with ctx.Pool(2) as pool:
        pool.starmap(_append_one, [(str(tmp_path), f"p{i}") for i in range(24)])
    names = pl.read_parquet(tmp_path / "points.parquet")["name"].to_list()
    assert sorted(names) == sorted(f"p{i}" for i in range(24))
