"""An unfinished point's state kept where the dataset is committed, so that a campaign goes on
from what is committed on any machine, not only on the one whose ``OUT/work/`` holds it.

A point's work directory (``OUT/work/<key>/``, not committed) holds its checkpoint, its tables
and ``meta.json``; :func:`keep` copies them after every stint into ``OUT/progress/<key>/``
(the checkpoint zstd-compressed, with its size and SHA-256 in ``pack.json``), and
:func:`restore` copies them back into a work directory that lacks a checkpoint. The copy is
written whole beside the old one and swapped in, so a crash while keeping leaves the previous
stint's copy; the point's row, once appended to ``points.parquet``, ends its kept copy
(:func:`forget`). The checkpoint restores bitwise, so a run resumed from the kept copy goes on
exactly as the run that wrote it would have.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pyarrow as pa

from granflow.errors import GranflowError

#: the kept checkpoint's name and its compression (zstd: ~2/3 of the raw size, ~10 ms per MB)
PACKED = "checkpoint.gfck.zst"
_LEVEL = 3


def keep(work_dir: Path, kept: Path) -> None:
    """Copy the checkpoint, ``meta.json`` and tables of ``work_dir`` into ``kept``
    (replacing what it held; nothing is kept while ``work_dir`` has no checkpoint)."""
    ck, meta = work_dir / "checkpoint.gfck", work_dir / "meta.json"
    if not (ck.exists() and meta.exists()):
        return
    tmp, old = kept.with_name(kept.name + ".tmp"), kept.with_name(kept.name + ".old")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    raw = ck.read_bytes()
    (tmp / PACKED).write_bytes(pa.Codec("zstd", compression_level=_LEVEL)
                               .compress(raw, asbytes=True))
    for f in (meta, *sorted(work_dir.glob("*.parquet"))):
        shutil.copy2(f, tmp / f.name)
    (tmp / "pack.json").write_text(json.dumps(
        {"checkpoint_bytes": len(raw), "sha256": hashlib.sha256(raw).hexdigest()}))
    shutil.rmtree(old, ignore_errors=True)
    if kept.exists():
        kept.rename(old)
    tmp.rename(kept)
    shutil.rmtree(old, ignore_errors=True)


def restore(kept: Path, work_dir: Path) -> bool:
    """Fill ``work_dir`` from the copy in ``kept`` (or the previous copy, if a crash came
    between the swap's two renames); returns whether there was one. A copy whose checkpoint
    does not match its recorded SHA-256 raises :class:`~granflow.errors.GranflowError`
    (nothing is written then)."""
    src = next((p for p in (kept, kept.with_name(kept.name + ".old"))
                if (p / "pack.json").exists()), None)
    if src is None:
        return False
    info = json.loads((src / "pack.json").read_text())
    raw = pa.decompress((src / PACKED).read_bytes(), info["checkpoint_bytes"],
                        codec="zstd", asbytes=True)
    if hashlib.sha256(raw).hexdigest() != info["sha256"]:
        raise GranflowError(f"the kept checkpoint in {src} does not match its SHA-256 in "
                            "pack.json: delete that directory to run the point from the start")
    work_dir.mkdir(parents=True, exist_ok=True)
    for f in src.iterdir():
        if f.name not in (PACKED, "pack.json"):
            shutil.copy2(f, work_dir / f.name)
    tmp = work_dir / "checkpoint.gfck.tmp"
    tmp.write_bytes(raw)
    tmp.rename(work_dir / "checkpoint.gfck")  # (last: a work directory with a checkpoint is whole)
    return True


def forget(kept: Path) -> None:
    """Remove the kept copy of a point whose row is written."""
    for p in (kept, kept.with_name(kept.name + ".tmp"), kept.with_name(kept.name + ".old")):
        shutil.rmtree(p, ignore_errors=True)
