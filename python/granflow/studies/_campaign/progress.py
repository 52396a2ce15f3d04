"""An unfinished point's state kept where the dataset is committed, so that a campaign goes on
from what is committed on any machine, not only on the one whose ``OUT/work/`` holds it.

A point's work directory (``OUT/work/<key>/``, not committed) holds its checkpoint, its tables
and ``meta.json``; :func:`keep` copies them after every stint into ``OUT/progress/<key>/``
(the checkpoint zstd-compressed, with its size and SHA-256 in ``pack.json``; the tables as
far as the study's rows read them, ``Study.kept_tables``), and
:func:`restore` copies them back into a work directory that lacks a checkpoint or is behind
the copy (:func:`ahead`). The copy is
written whole beside the old one and swapped in, so a crash while keeping leaves the previous
stint's copy; the point's row, once appended to ``points.parquet``, ends its kept copy
(:func:`forget`), or, while other points still start from its final state, leaves its
checkpoint alone (:func:`slim`). The checkpoint restores bitwise, so a run resumed from the
kept copy goes on exactly as the run that wrote it would have.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Mapping
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from granflow.errors import GranflowError
from granflow.io import atomic_path

#: the kept checkpoint's name and its compression (zstd: ~2/3 of the raw size, ~10 ms per MB)
PACKED = "checkpoint.gfck.zst"
_LEVEL = 3


def keep(work_dir: Path, kept: Path, tables: Mapping[str, pa.Table]) -> None:
    """Copy the checkpoint and ``meta.json`` of ``work_dir`` into ``kept`` with ``tables``
    (``Study.kept_tables``), replacing what it held; nothing is kept while ``work_dir`` has
    no checkpoint."""
    ck, meta = work_dir / "checkpoint.gfck", work_dir / "meta.json"
    if not (ck.exists() and meta.exists()):
        return
    tmp, old = _beside(kept, ".tmp"), _beside(kept, ".old")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    raw = ck.read_bytes()
    (tmp / PACKED).write_bytes(pa.Codec("zstd", compression_level=_LEVEL)
                               .compress(raw, asbytes=True))
    shutil.copy2(meta, tmp / meta.name)
    for name, tab in tables.items():
        _write_table(tab, tmp / f"{name}.parquet")
    (tmp / "pack.json").write_text(json.dumps(
        {"checkpoint_bytes": len(raw), "sha256": hashlib.sha256(raw).hexdigest()}))
    shutil.rmtree(old, ignore_errors=True)
    if kept.exists():
        kept.rename(old)
    tmp.rename(kept)
    shutil.rmtree(old, ignore_errors=True)


def _write_table(tab: pa.Table, f: Path) -> None:
    """``tab`` as Parquet, small: zstd over the floats split by byte (sampled floats share
    their high bytes: ~3/4 of snappy's size on a channel's tables); lossless."""
    floats = [n for n, t in zip(tab.schema.names, tab.schema.types, strict=True)
              if pa.types.is_floating(t)]
    pq.write_table(tab, f, compression="zstd", compression_level=9, use_dictionary=False,
                   column_encoding=dict.fromkeys(floats, "BYTE_STREAM_SPLIT"))


def _beside(kept: Path, suffix: str) -> Path:
    """The directory beside ``kept`` that a swap writes (".tmp") or moves it to (".old")."""
    return kept.with_name(kept.name + suffix)


def _source(kept: Path) -> Path | None:
    """The whole copy: ``kept``, or the previous one if a crash came between the swap's two
    renames; None if there is neither."""
    return next((p for p in (kept, _beside(kept, ".old")) if (p / "pack.json").exists()),
                None)


def restore(kept: Path, work_dir: Path) -> bool:
    """Fill ``work_dir`` from the copy in ``kept`` (:func:`_source`), replacing what it held;
    returns whether there was one. A copy whose checkpoint
    does not match its recorded SHA-256 raises :class:`~granflow.errors.GranflowError`
    (nothing is written then)."""
    src = _source(kept)
    if src is None:
        return False
    info = json.loads((src / "pack.json").read_text())
    raw = pa.decompress((src / PACKED).read_bytes(), info["checkpoint_bytes"],
                        codec="zstd", asbytes=True)
    if hashlib.sha256(raw).hexdigest() != info["sha256"]:
        raise GranflowError(f"the kept checkpoint in {src} does not match its SHA-256 in "
                            "pack.json: delete that directory to run the point from the start")
    work_dir.mkdir(parents=True, exist_ok=True)
    # (a stale work directory's checkpoint goes first: until the copy's is in, the directory
    # has none, so a crash here means restoring again)
    for f in (work_dir / "checkpoint.gfck", *work_dir.glob("*.parquet")):
        f.unlink(missing_ok=True)
    for f in src.iterdir():
        if f.name not in (PACKED, "pack.json"):
            shutil.copy2(f, work_dir / f.name)
    with atomic_path(work_dir / "checkpoint.gfck") as tmp:  # (last: then the directory is whole)
        tmp.write_bytes(raw)
    return True


def ahead(kept: Path, work_dir: Path) -> bool:
    """Whether the copy in ``kept`` is further on than ``work_dir``: it has more stints in
    its ``meta.json`` history, or ``work_dir`` has no checkpoint (a work directory left on a
    machine that a later session ran past, elsewhere, is stale)."""
    src = _source(kept)
    if src is None:
        return False
    if not ((work_dir / "checkpoint.gfck").exists() and (work_dir / "meta.json").exists()):
        return True

    def stints(d: Path) -> int:
        return len(json.loads((d / "meta.json").read_text()).get("history", []))

    return stints(src) > stints(work_dir)


def slim(kept: Path) -> None:
    """Reduce the kept copy of a finished point whose final state other points still start
    from (a branch's parent) to what they read: its checkpoint, ``pack.json`` and
    ``meta.json``. Its row is written; its tables (a W = 60 channel's reach ~6 MB by its
    end) would only be committed again and again until the last of them is done."""
    for src in (kept, _beside(kept, ".old")):
        for f in (src.glob("*.parquet") if src.is_dir() else ()):
            f.unlink()


def forget(kept: Path) -> None:
    """Remove the kept copy of a point whose row is written."""
    for p in (kept, _beside(kept, ".tmp"), _beside(kept, ".old")):
        shutil.rmtree(p, ignore_errors=True)
