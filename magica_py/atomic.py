"""Output files written whole or not at all.

Every file a command writes for the user (a baked glTF, VRM or BVH, a batch job's row and
summary tables, bench reports and plots, a saved scene, a starter scene) is written under a
temporary name beside its final one and renamed when complete: a reader sees the old file or the new one,
never half of one. If the writing ends early, by an error, ^C or a job scheduler's SIGTERM
(``cli.Terminated``: a ``BaseException``, like ``KeyboardInterrupt``), the temporary file is
removed and the final path is left as it was. (The Rerun recording keeps its own temporary
file, ``sinks.rerun_sink``, because it is written frame by frame.)
"""
from __future__ import annotations

import os
import pathlib
from contextlib import contextmanager

SUFFIX = ".partial"


@contextmanager
def replacing(path):
    """The temporary path to write ``path``'s new content to (``path`` + ``SUFFIX``, in the same
    folder): renamed over ``path`` when the block ends normally, removed when it ends by any
    exception."""
    path = pathlib.Path(path)
    tmp = path.with_name(path.name + SUFFIX)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        try:
            os.unlink(tmp)
        except OSError:   # never created (missing or unwritable folder): the original error stands
            pass


def write_text(path, text: str, encoding: str = "utf-8") -> None:
    """``path.write_text(text)``, whole or not at all."""
    with replacing(path) as tmp:
        tmp.write_text(text, encoding=encoding)


def write_bytes(path, data: bytes) -> None:
    """``path.write_bytes(data)``, whole or not at all."""
    with replacing(path) as tmp:
        tmp.write_bytes(data)


def save_figure(fig, path, **options) -> None:
    """``fig.savefig(path, **options)`` (matplotlib), whole or not at all; the format is the
    final name's extension, as savefig would infer it."""
    path = pathlib.Path(path)
    with replacing(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip(".") or None, **options)
