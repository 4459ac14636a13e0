"""LiDAR scans (an (N, 4) float32 array of x, y, z, intensity): ``fog`` one,
``rain`` or ``snow`` on one, or ``wet`` its ground."""
from ._brume import lidar_fog as fog
from ._brume import lidar_rain as rain
from ._brume import lidar_snow as snow
from ._brume import lidar_wet as wet

__all__ = ["fog", "rain", "snow", "wet"]
