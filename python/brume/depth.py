"""Depth: every source to a range map (``convert``), range preparation (``prepare``), and the
completion of a sparse map guided by its image (``complete``)."""
from ._brume import depth_complete as complete
from ._brume import depth_convert as convert
from ._brume import depth_prepare as prepare

__all__ = ["complete", "convert", "prepare"]
