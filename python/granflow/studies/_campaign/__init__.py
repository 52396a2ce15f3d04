"""What the campaign studies share: the engine (:mod:`.engine`: the resumable stint loop and
:func:`reanalyse`, driven by a :class:`Study`), the command line (:mod:`.command`), the
reports' helpers (:mod:`.report`), and the cell campaign that reproduce_002, cross_scene and
seed_coverage run (:mod:`.cell`).

A campaign's dataset is a directory of Parquet tables that grow one finished point at a time:
a finished point is one row of ``OUT/points.parquet`` holding the point's fields and its
measurements, and its rows of further tables (``Study.tables``) are appended with it, so a
campaign that is stopped loses only its unfinished points, which go on from their
checkpoints under ``OUT/work/``, or, on a new machine, from the copy of them that the dataset
keeps in ``OUT/progress/`` (:mod:`.progress`).
"""

from .command import cli
from .engine import (
    ERROR_STATES,
    Study,
    add_final_rows,
    done_keys,
    error_state,
    fmt,
    keys_done,
    point_of,
    reanalyse,
    run_point,
    run_points,
    write_rows,
)
from .report import (
    core_seconds,
    cost,
    dask_recipe,
    md_table,
    paper_scale_estimate,
    plot_campaign_se,
    pm,
    pm_column,
    run_seconds,
    sig,
    sig_text,
    span,
    span_of,
)

__all__ = ["ERROR_STATES", "Study", "add_final_rows", "cli", "core_seconds", "cost",
           "dask_recipe", "done_keys", "error_state", "fmt", "keys_done", "md_table",
           "paper_scale_estimate", "plot_campaign_se", "pm", "pm_column", "point_of",
           "reanalyse", "run_point", "run_points", "run_seconds", "sig", "sig_text", "span",
           "span_of", "write_rows"]
