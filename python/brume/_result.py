"""The small result object every brume function returns."""
from types import SimpleNamespace

import numpy as np


class Result(SimpleNamespace):
    """Named results of a brume call: numpy arrays (``rgb``, ``transmission``,
    ``scale`` ...) and ``record``, the run's parameter record as a dict (the
    same JSON the CLI writes with ``--record``; pass it to
    ``brume.write_image(..., record=r.record)`` to embed it)."""

    def __repr__(self):
        parts = []
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                parts.append(f"{k}=<{v.dtype} {'x'.join(map(str, v.shape))}>")
            elif k == "record":
                parts.append("record={...}" if v else "record=None")
            else:
                parts.append(f"{k}={v!r}")
        return "brume.Result(" + ", ".join(parts) + ")"

    def __getitem__(self, key):
        return self.__dict__[key]

    def keys(self):
        return self.__dict__.keys()
