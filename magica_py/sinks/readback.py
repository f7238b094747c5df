"""Read a magica_py recording back with rerun's own chunk reader (docs/tech-notes.md §4, route A).

``Recording(path)`` loads the file once and answers per entity / component queries:

    rec = Recording("replays/tail_orbit.rrd")
    frames, rows = rec.rows("/world/cloths/tail/particles", "Points3D:positions")
    rows[k]            # (n, 3) float32 as stored (bit for bit what was logged)
    rec.scalars("/metrics/max_speed")   -> (frames, values float64)
    rec.static_value("/replay/scene", "yaml")

Component names follow rerun's ``Archetype:field`` convention; AnyValues are stored under
their bare name (``local_position``).
"""
from __future__ import annotations

import os
import pathlib
from collections import defaultdict

import numpy as np


class RecordingError(ValueError):
    """A file that is not a readable magica_py recording."""


class Recording:
    def __init__(self, path: str | os.PathLike):
        import pyarrow as pa
        from rerun.chunk import RrdReader

        self.path = pathlib.Path(path)
        if not self.path.is_file():
            raise RecordingError(f"{path}: no such recording file")
        try:
            reader = RrdReader(self.path)
            chunks = list(reader.stream())
            self.blueprint_count = len(reader.blueprints())
        except Exception as exc:  # noqa: BLE001 - the reader raises RuntimeError / OSError
            raise RecordingError(f"{path}: not a readable .rrd recording ({exc})") from exc
        self._pa = pa
        self.temporal: dict[str, list] = defaultdict(list)   # entity -> record batches
        self.static: dict[str, list] = defaultdict(list)
        for chunk in chunks:
            batch = chunk.to_record_batch()
            entity = batch.schema.metadata.get(b"rerun:entity_path", b"").decode()
            (self.static if chunk.is_static else self.temporal)[entity].append(batch)

    # -------------------------------------------------------------- structure
    @property
    def entities(self) -> list[str]:
        return sorted(set(self.temporal) | set(self.static))

    def components(self, entity: str) -> list[str]:
        names = set()
        for b in self.temporal.get(entity, []) + self.static.get(entity, []):
            names.update(f.name for f in b.schema if f.metadata and f.metadata.get(b"rerun:kind") == b"data")
        return sorted(names)

    def timeline_values(self, timeline: str = "frame") -> np.ndarray:
        """Sorted unique values of a timeline over the whole recording (int64; ns for durations)."""
        values = [self._index(b, timeline) for bs in self.temporal.values() for b in bs
                  if timeline in b.schema.names]
        if not values:
            return np.zeros(0, np.int64)
        return np.unique(np.concatenate(values))

    # -------------------------------------------------------------- data
    def table(self, entity: str, component: str, timeline: str = "frame"):
        pa = self._pa
        batches = [b for b in self.temporal.get(entity, []) if component in b.schema.names]
        if not batches:
            return None
        tables = [pa.Table.from_batches([b]).select([timeline, component]) for b in batches]
        return pa.concat_tables(tables).sort_by(timeline)

    def rows(self, entity: str, component: str, timeline: str = "frame") -> tuple[np.ndarray, list[np.ndarray]]:
        """(timeline values (n,), one array per logged row): (k, width) for fixed-size-list items."""
        tbl = self.table(entity, component, timeline)
        if tbl is None:
            raise RecordingError(f"{self.path}: no {component!r} logged on {entity!r}")
        index = self._index_column(tbl.column(timeline))
        col = tbl.column(component).combine_chunks()
        out = []
        for i in range(len(col)):
            out.append(_row_array(col[i].values))
        return index, out

    def stacked(self, entity: str, component: str, timeline: str = "frame") -> tuple[np.ndarray, np.ndarray]:
        """Like ``rows`` but stacked into one (n_rows, k, width) array (rows must agree in shape)."""
        index, rows = self.rows(entity, component, timeline)
        return index, np.stack(rows) if rows else np.zeros((0,))

    def scalars(self, entity: str, timeline: str = "frame") -> tuple[np.ndarray, np.ndarray]:
        index, rows = self.rows(entity, "Scalars:scalars", timeline)
        return index, np.array([r[0] if r.size else np.nan for r in rows], np.float64)

    def static_value(self, entity: str, component: str):
        """The value of a static component: a python list (strings) or a numpy array."""
        for b in self.static.get(entity, []):
            if component in b.schema.names:
                value = b.column(component)[0].values
                if self._pa.types.is_string(value.type) or self._pa.types.is_large_string(value.type):
                    return value.to_pylist()
                return _row_array(value)
        raise RecordingError(f"{self.path}: no static {component!r} on {entity!r}")

    def text_rows(self, entity: str, component: str, timeline: str = "frame") -> list[tuple[int, str]]:
        tbl = self.table(entity, component, timeline)
        if tbl is None:
            return []
        index = self._index_column(tbl.column(timeline))
        col = tbl.column(component).combine_chunks()
        out = []
        for i in range(len(col)):
            for text in col[i].values.to_pylist():
                out.append((int(index[i]), text))
        return out

    # -------------------------------------------------------------- helpers
    def _index(self, batch, timeline):
        return self._index_column(batch.column(timeline))

    def _index_column(self, column) -> np.ndarray:
        pa = self._pa
        if hasattr(column, "combine_chunks"):
            column = column.combine_chunks()
        if pa.types.is_duration(column.type):
            column = column.cast(pa.int64())
        return column.to_numpy(zero_copy_only=False)


def _row_array(values) -> np.ndarray:
    """Flatten one row's values: fixed-size lists -> (k, width), primitives -> (k,)."""
    import pyarrow as pa

    if pa.types.is_list(values.type) or pa.types.is_large_list(values.type):
        return _row_array(values.flatten())   # e.g. line strips: all points of the row
    if pa.types.is_fixed_size_list(values.type):
        width = values.type.list_size
        return values.flatten().to_numpy(zero_copy_only=False).reshape(-1, width)
    if pa.types.is_string(values.type) or pa.types.is_large_string(values.type):
        return np.array(values.to_pylist(), dtype=object)
    return values.to_numpy(zero_copy_only=False)
