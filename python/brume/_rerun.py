"""brume.rerun: repeat the run a parameter record describes, on arrays."""
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
    and hash its files). Commands: the effects with an array form (haze,
    aerial, fog, dof, and the chain haze+dof).
    """
    if not isinstance(record, dict) or record.get("tool") != "brume" or "job" not in record:
        raise ValueError("brume.rerun(): record is not a brume parameter record (a dict with \"tool\": \"brume\" "
                         "and \"job\"); pass a Result's .record or a record JSON loaded with json.load")
    command = record.get("command")
    if command not in _REPLAYABLE:
        raise ValueError(f"brume.rerun(): the record's command {command!r} is not one of "
                         f"{', '.join(sorted(_REPLAYABLE))}; rerun other records with `brume run`")
    return _REPLAYABLE[command](rgb, range, job=_brume._record_job(record), **keywords)
