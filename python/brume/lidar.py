"""LiDAR scans: ``fog`` one (an (N, 4) float32 array of x, y, z, intensity)."""
from ._brume import lidar_fog as fog

__all__ = ["fog"]
