"""Recordings that survive a hard kill: every saved episode stays on disk as a complete LeRobot v3 dataset.

LeRobot's writer keeps its parquet files (frames, episode metadata) open across episodes and writes their footers
only when the dataset is finalized, so a process killed with SIGKILL (the OOM killer, a power cut) leaves files
that no reader opens: the whole recording is lost, and ``--resume`` fails the same way. Signals that can be caught
are handled by :mod:`lerobot_efm.recording`; this module covers the one that cannot:

* :func:`seal_episode_files` closes every file after each saved episode and continues in new ones, exactly as
  LeRobot's own ``LeRobotDataset.resume`` does (one data, metadata and video file per episode). Worst case: the
  episode being recorded is lost, and a kill during the few milliseconds of its save leaves debris behind.
* LeRobot rewrites ``meta/info.json`` and ``stats.json`` (and ``tasks.parquet`` for a new task) in place at
  every saved episode (truncate, then write), so a kill in that window leaves them empty.
  :func:`seal_episode_files` keeps a copy of those files as they were at the seal (``meta/last_sealed/``, written
  atomically); the writer removes it when the dataset is finalized normally.
* :func:`repair_dataset` removes that debris (files without a parquet footer, frames and videos no saved episode
  refers to), restores unreadable metadata files from the copy and recomputes ``info.json`` and ``stats.json``
  from the saved episodes' metadata. ``--resume=true`` runs it before appending.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from lerobot.datasets.compute_stats import aggregate_stats
from lerobot.datasets.io_utils import load_info, write_info, write_stats
from lerobot.datasets.lerobot_dataset import LeRobotDataset

log = logging.getLogger(__name__)

SEALED_COPY_DIR = "meta/last_sealed"  # the metadata files as they were at the last seal
# the metadata files LeRobot rewrites in place (truncate, then write) when it saves an episode
REWRITTEN_META_FILES = ("meta/info.json", "meta/stats.json", "meta/tasks.parquet")


def seal_episode_files(dataset: LeRobotDataset) -> None:
    """Close the files the last episode went into (parquet footers written) and continue in fresh files."""
    dataset.finalize()
    fresh = LeRobotDataset.resume(dataset.repo_id, root=dataset.root)
    dataset.meta, dataset.writer, dataset._is_finalized = fresh.meta, fresh.writer, False
    dataset.reader = None
    keep_sealed_copy(dataset.root)


def keep_sealed_copy(root: str | Path) -> None:
    """Copy the metadata files LeRobot rewrites in place to :data:`SEALED_COPY_DIR` (each copy atomic: written
    next to its target, then renamed), so that :func:`repair_dataset` can restore one a kill cut short."""
    root = Path(root)
    (root / SEALED_COPY_DIR).mkdir(parents=True, exist_ok=True)
    for rel in REWRITTEN_META_FILES:
        source = root / rel
        if source.exists():
            target = root / SEALED_COPY_DIR / source.name
            shutil.copyfile(source, target.with_suffix(".tmp"))
            os.replace(target.with_suffix(".tmp"), target)


def drop_sealed_copy(root: str | Path) -> None:
    """Remove the copy once the dataset is finalized normally (a finished dataset carries no extra files)."""
    shutil.rmtree(Path(root) / SEALED_COPY_DIR, ignore_errors=True)


def _readable_meta(path: Path) -> bool:
    if path.suffix == ".parquet":
        return _readable(path)
    try:
        json.loads(path.read_text())
        return True
    except (OSError, ValueError):  # empty or cut short by a kill mid-write
        return False


def _restore_unreadable_meta(root: Path) -> list[Path]:
    """Put back, from the sealed copy, every rewritten metadata file that a kill left unreadable (a
    ``stats.json`` without a copy is removed instead: :func:`repair_dataset` recomputes it); returns them."""
    restored = []
    for rel in REWRITTEN_META_FILES:
        path = root / rel
        if not path.exists() or _readable_meta(path):
            continue
        copy = root / SEALED_COPY_DIR / path.name
        if not copy.exists():
            if path.name == "stats.json":
                path.unlink()
                restored.append(path)
                continue
            raise ValueError(
                f"{path} is unreadable (a kill while LeRobot rewrote it) and {copy} holds no copy to restore"
            )
        shutil.copyfile(copy, path)
        restored.append(path)
    return restored


def _readable(path: Path) -> bool:
    try:
        pq.ParquetFile(path).metadata  # noqa: B018 (reads the footer)
        return True
    except Exception:  # a file cut before its footer: pyarrow's ArrowInvalid, OSError, ...
        return False


def repair_dataset(root: str | Path) -> list[Path]:
    """Make the dataset at ``root`` consistent with its readable episode metadata after a hard kill; returns the
    files removed (only unreadable ones and frames/videos of episodes whose save never completed)."""
    root = Path(root)
    restored = _restore_unreadable_meta(root)
    removed = [p for p in sorted(root.glob("meta/episodes/**/*.parquet")) if not _readable(p)]
    removed += [p for p in sorted(root.glob("data/**/*.parquet")) if not _readable(p)]
    for path in removed:
        path.unlink()
    episode_files = sorted(root.glob("meta/episodes/**/*.parquet"))
    rows = [row for path in episode_files for row in pq.read_table(path).to_pylist()]
    rows.sort(key=lambda r: r["episode_index"])
    info = load_info(root)

    def chunk_file(row, prefix):
        return row[f"{prefix}/chunk_index"], row[f"{prefix}/file_index"]

    used_data = {
        info.data_path.format(chunk_index=c, file_index=f) for c, f in (chunk_file(r, "data") for r in rows)
    }
    orphans = [p for p in root.glob("data/**/*.parquet") if str(p.relative_to(root)) not in used_data]
    for key in [k for k, ft in info.features.items() if ft["dtype"] == "video"]:
        used = {
            info.video_path.format(video_key=key, chunk_index=c, file_index=f)
            for c, f in (chunk_file(r, f"videos/{key}") for r in rows)
        }
        orphans += [p for p in root.glob(f"videos/{key}/**/*.mp4") if str(p.relative_to(root)) not in used]
    for path in orphans:
        path.unlink()
    removed += orphans

    frames = sum(int(r["length"]) for r in rows)
    if removed or restored or info.total_episodes != len(rows) or info.total_frames != frames:
        log.warning(
            "repaired %s after an unfinished save: %d episodes, %d frames kept; removed %s; rewritten %s",
            root,
            len(rows),
            frames,
            [str(p.relative_to(root)) for p in removed],
            [str(p.relative_to(root)) for p in restored],
        )
        info.total_episodes, info.total_frames = len(rows), frames
        info.splits = {"train": f"0:{len(rows)}"}
        write_info(info, root)
        if rows:
            write_stats(aggregate_stats([_episode_stats(r) for r in rows]), root)
    return removed


def _episode_stats(row: dict) -> dict[str, dict[str, np.ndarray]]:
    """One episode's statistics from its metadata row (columns ``stats/<feature>/<statistic>``)."""
    stats: dict[str, dict[str, np.ndarray]] = {}
    for column, value in row.items():
        if column.startswith("stats/") and value is not None:
            feature, name = column[len("stats/") :].rsplit("/", 1)
            stats.setdefault(feature, {})[name] = np.asarray(value)
    return stats
