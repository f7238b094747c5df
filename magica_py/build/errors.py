"""Build errors name the cloth and the offending bones."""
from __future__ import annotations


class BuildError(ValueError):
    """A cloth that cannot be built: ``cloth`` is the cloth's name, ``message`` what is wrong."""

    def __init__(self, cloth: str, message: str):
        self.cloth = cloth
        self.message = message
        super().__init__(f"cloth {cloth!r}: {message}")

    def __reduce__(self):  # unpickles as itself (Dask workers, multiprocessing)
        return (type(self), (self.cloth, self.message), self.__dict__)
