"""brume: physically based, depth-aware atmospheric and lens effects for RGB-D
images, numpy in and numpy out.

Every function takes the parameters of the matching ``brume`` command as
keyword arguments, named after its flags (``--f-number`` -> ``f_number``;
``--lambda`` -> ``lambda_``, or ``**{"lambda": ...}``), checked by the same
declarations (TypeError for an unknown keyword or a wrong type, ValueError for
a value out of range), and returns a :class:`Result` with numpy arrays and the
run's ``record``. ``help(brume.haze)`` lists every keyword with its unit,
default and range.

Images are H x W x 3 (or x 4, alpha ignored) linear RGB; ranges H x W float
metres along each pixel's ray (NaN: unknown). float32 is read in place,
float64 converted once, uint8/uint16 need ``transfer="srgb"|"linear"``. The
GIL is released while an effect runs. See docs/python.md.
"""
# The commands' functions are re-exported by name (here and in depth.py,
# lidar.py, sky.py) so that editors and type checkers see them; the list of
# commands (src/jobs/commands.cpp) is the source: each command's public name
# must resolve here, or test_every_command_of_the_list_reaches_python fails.
from ._brume import (__version__, aerial, blur, dof, fog, haze, haze_dof, max_pixels, rain, random_params, read_image,
                     set_max_pixels, snow, wet, write_image)
from ._result import Result
from . import depth, lidar, sky
from ._rerun import rerun

__all__ = ["Result", "__version__", "aerial", "blur", "depth", "dof", "fog", "haze", "haze_dof", "lidar", "max_pixels", "rain", "random_params",
           "read_image", "rerun", "set_max_pixels", "sky", "snow", "wet", "write_image"]
