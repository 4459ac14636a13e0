"""Preetham skies: ``render`` one, ``fit`` the turbidity of a sky photo."""
from ._brume import sky_fit as fit
from ._brume import sky_render as render

__all__ = ["fit", "render"]
