"""brume.rerun: repeat the run a parameter record describes, on arrays."""
import hashlib

import numpy as np

from . import _brume

# The commands of the library's list (brume/command.hpp) that this module runs
# on arrays and that take a record's job: {command: function}.
_REPLAYABLE = {c["name"]: getattr(_brume, c["function"]) for c in _brume._commands()
               if c["replays"] and c["arrays"] == ["rgb", "range"]}


def rerun(record, rgb, range, **keywords):
    """Repeat the effect run that ``record`` describes on ``rgb`` and ``range``
    (a Result's ``record``, or the JSON a ``brume`` command wrote with
    ``--record`` or embedded in its output), bit for bit on the CPU backend.

    The same as ``brume.<command>(rgb, range, job=record["job"], **keywords)``:
    the record's job is read as ``brume run`` reads it -- every parameter is
    recorded, so none counts as given, and a haze record holding both
    ``visibility`` and the default ``kappa-a`` replays (spreading the job's
    blocks as keywords, ``**record["job"]["haze"]``, would give both and be
    refused), and a record of an older schema runs under the rules it ran
    under (its job completed as ``brume run`` completes it: a schema-2 haze or
    fog record keeps the sky at S_max). ``keywords`` override single values (``threads=``,
    ``backend=`` ...). The inputs are the arrays given, not the record's files:
    pass the same pixels for the same bits (a CLI record's ``inputs`` name
    and hash its files). What it reads besides them is checked as ``brume
    run`` checks files: a scan given as ``lidar=`` against the recorded one
    (a CLI record's by the SHA-256 of its points, a Python record's by their
    count), and the calibration a height-profile fog read for a scan's pose. Commands: the effects with an array form (haze,
    aerial, fog, dof, and the chain haze+dof).
    """
    if not isinstance(record, dict) or record.get("tool") != "brume" or "job" not in record:
        raise ValueError("brume.rerun(): record is not a brume parameter record (a dict with \"tool\": \"brume\" "
                         "and \"job\"); pass a Result's .record or a record JSON loaded with json.load")
    command = record.get("command")
    if command not in _REPLAYABLE:
        raise ValueError(f"brume.rerun(): the record's command {command!r} is not one of "
                         f"{', '.join(sorted(_REPLAYABLE))}; rerun other records with `brume run`")
    _check_read_inputs(record, keywords)
    return _REPLAYABLE[command](rgb, range, job=_brume._record_job(record), **keywords)


def _check_read_inputs(record, keywords):
    """What the replay reads besides the arrays, as `brume run` checks a record's
    files: the calibration that placed a scan in a height-profile fog (read
    from its path), and the scan given as lidar= against the one recorded
    (a CLI record hashes the .bin file, which is the float32 points; a Python
    record counts them)."""
    inputs = record.get("inputs", {}) if isinstance(record.get("inputs"), dict) else {}
    calib = inputs.get("kitti_calib")
    if isinstance(calib, dict) and isinstance(calib.get("path"), str) and isinstance(calib.get("sha256"), str):
        try:
            digest = _brume._sha256_file(calib["path"])  # a regular file, as brume reads inputs
        except OSError as e:
            raise ValueError(f"brume.rerun(): the record's input {calib['path']!r} cannot be read "
                             f"({e.strerror or e}); restore the calibration file or run from the directory the "
                             f"record was made in")
        if digest != calib["sha256"]:
            raise ValueError(f"brume.rerun(): the record's input {calib['path']!r} has changed since the record "
                             f"was made (SHA-256 differs); the run would not be the one recorded")
    scan, points = inputs.get("lidar"), keywords.get("lidar")
    if isinstance(scan, dict) and points is not None:
        a = np.ascontiguousarray(np.asarray(points), dtype="<f4")
        if isinstance(scan.get("points"), int) and a.shape[0] != scan["points"]:
            raise ValueError(f"brume.rerun(): lidar= holds {a.shape[0]} points, the recorded scan "
                             f"{scan['points']}; pass the frame's scan")
        if scan.get("source") != "numpy" and isinstance(scan.get("sha256"), str) and \
                hashlib.sha256(a.tobytes()).hexdigest() != scan["sha256"]:
            raise ValueError(f"brume.rerun(): lidar= is not the recorded scan {scan.get('path', '')!r} (the "
                             f"SHA-256 of its float32 points differs from the file's); pass the same points")
