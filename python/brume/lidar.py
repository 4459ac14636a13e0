"""LiDAR scans (an (N, 4) float32 array of x, y, z, intensity): ``fog`` one,
or ``rain`` on one."""
from ._brume import lidar_fog as fog
from ._brume import lidar_rain as rain

__all__ = ["fog", "rain"]
