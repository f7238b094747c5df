"""The one error type of the importers: it names the file, the place in it and the problem."""
from __future__ import annotations

from pathlib import Path


class AssetError(ValueError):
    """A file that cannot be imported.

    ``file`` is the path as given, ``where`` the location inside it (a JSON path such as
    ``extensions.VRMC_springBone.springs[0].joints[3].node``, or ``line 42`` for a BVH) and
    ``message`` what was found and what was expected.
    """

    def __init__(self, file, where: str, message: str):
        self.file = Path(file) if file is not None else None
        self.where = where
        self.message = message
        location = f"{self.file}" if self.file is not None else "<memory>"
        if where:
            location += f": {where}"
        super().__init__(f"{location}: {message}")

    def __reduce__(self):  # unpickles as itself (Dask workers, multiprocessing)
        return (type(self), (self.file, self.where, self.message), self.__dict__)
