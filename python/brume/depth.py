"""Depth: every source to a range map (``convert``), range preparation (``prepare``), the
completion of a sparse map guided by its image (``complete``) and the disparity of a rectified
stereo pair (``stereo``)."""
from ._brume import depth_complete as complete
from ._brume import depth_convert as convert
from ._brume import depth_prepare as prepare
from ._brume import depth_stereo as stereo

__all__ = ["complete", "convert", "prepare", "stereo"]
