"""Depth: every source to a range map (``convert``) and range preparation (``prepare``)."""
from ._brume import depth_convert as convert
from ._brume import depth_prepare as prepare

__all__ = ["convert", "prepare"]
