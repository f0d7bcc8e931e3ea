"""Reading an ``.rrd`` file back (tests, benchmarks): rows per entity path through rerun's own reader."""

from __future__ import annotations

from pathlib import Path


def read_rrd(path: str | Path) -> dict[str, list[dict]]:
    """All rows of the first recording of an ``.rrd`` file, per entity path (without the leading ``/``),
    through rerun's reader (``rerun.experimental.RrdReader``). Each row maps column names (timelines such as
    ``step``; components such as ``Scalars:scalars``) to python values; static rows have no ``step``."""
    from rerun.experimental import RrdReader

    out: dict[str, list[dict]] = {}
    for chunk in RrdReader(str(path)).stream():
        data = chunk.to_record_batch().to_pydict()
        data.pop("rerun.controls.RowId", None)
        columns = list(data)
        rows = out.setdefault(chunk.entity_path.lstrip("/"), [])
        rows.extend({c: data[c][i] for c in columns} for i in range(chunk.num_rows))
    for rows in out.values():
        rows.sort(key=lambda r: (r.get("step") is not None, r.get("step") or 0, r.get("log_tick") or 0))
    return out
