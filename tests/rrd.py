"""An .rrd file read back: its temporal columns per entity path and its static ones."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr


def read_rrd(path) -> dict[str, dict[str, np.ndarray]]:
    """Temporal columns per entity path (time-sorted, chunks concatenated), plus static ones
    under the key ``"static"``."""
    store = rr.chunk.RrdReader(path).stream().collect()
    parts: dict[str, list[pa.RecordBatch]] = {}
    static: dict[str, pa.RecordBatch] = {}
    for chunk in store.stream().to_chunks():
        rb = chunk.to_record_batch()
        if chunk.is_static:
            static[chunk.entity_path] = rb
        else:
            parts.setdefault(chunk.entity_path, []).append(rb)
    out: dict[str, dict[str, np.ndarray]] = {}
    for path, batches in parts.items():
        cols: dict[str, list[np.ndarray]] = {}
        for rb in batches:
            for name in rb.schema.names:
                if name.startswith("rerun.controls"):
                    continue
                col = rb.column(name)
                if name in ("time", "timestamp", "acceleration_mg"):
                    cols.setdefault(name, []).append(col.cast(pa.int64()).to_numpy())
                else:
                    flat = col
                    while pa.types.is_list(flat.type) or pa.types.is_fixed_size_list(flat.type):
                        flat = flat.flatten()
                    if pa.types.is_string(flat.type):
                        continue  # labels
                    values = flat.to_numpy(zero_copy_only=False).astype(np.float64)
                    cols.setdefault(name, []).append(values.reshape(len(col), -1))
        merged = {k: np.concatenate(v) for k, v in cols.items()}
        order = np.argsort(merged.get("time", merged.get("acceleration_mg")), kind="stable")
        out[path] = {k: v[order] for k, v in merged.items()}
    out["static"] = static  # type: ignore[assignment]
    return out


def scalars(data, path) -> np.ndarray:
    return data[path]["Scalars:scalars"].reshape(len(data[path]["time"]), -1)
