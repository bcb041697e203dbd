"""One rule set for turning values into JSON, and dataclasses back from it.

:func:`json_safe` makes a value that :func:`json.dumps` takes with
``allow_nan=False``, by these rules, everywhere in imu-square (``--json``
outputs, the history's JSON columns, alerts, MCAP summaries):

- None, booleans, text and integers stay as they are (an ``int`` subclass
  becomes a plain ``int``);
- a finite float stays; NaN and ±inf become None (``null``): no JSON parser
  reads ``NaN``, and a missing number is what they mean here;
- numpy scalars and arrays become Python numbers and (nested) lists;
- dicts keep their order, with their keys as text; lists and tuples become lists;
- paths become their text, datetimes and dates their ISO 8601 text;
- a dataclass becomes the dict of its fields, in their order;
- anything else raises :class:`JsonValueError`, naming where it was.

With ``urad=True`` a float under a key holding ``_rad`` (an angle in radians)
is written in µrad = µm/m under the key with ``_urad``, as every output shows
angles (radians inside, µm/m outside).

:func:`from_json` builds a dataclass back from such a dict, converting each
field by its annotation.
"""

import dataclasses
import functools
import math
import os
import types
import typing
from collections.abc import Mapping
from datetime import date

from imu_square.units import URAD


class JsonValueError(TypeError):
    """A value with no JSON form (a programming error, not a user's).

    Attributes
    ----------
    value : object
        The value.
    """

    def __init__(self, where, value):
        super().__init__(f"{where}: cannot be sent as JSON: {type(value).__name__} {value!r}")
        self.value = value


def json_safe(value, where="value", *, urad=False):
    """``value`` as JSON values only, by the module's rules.

    Parameters
    ----------
    value : object
        Anything the rules cover.
    where : str
        What ``value`` is, for the error message; items add ``.key`` and ``[i]``.
    urad : bool
        Write floats under ``*_rad*`` keys in µrad under ``*_urad*`` keys.

    Returns
    -------
    object
        Dicts with text keys, lists, text, int, finite float, bool or None.

    Raises
    ------
    JsonValueError
        For a value of any other type.
    """
    if value is None or isinstance(value, str | bool):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    if hasattr(value, "tolist") and hasattr(value, "dtype"):  # numpy scalar or array
        return json_safe(value.tolist(), where, urad=urad)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            item = json_safe(item, f"{where}.{key}", urad=urad)
            if urad and isinstance(item, float) and "_rad" in str(key):
                key, item = str(key).replace("_rad", "_urad"), item / URAD
            out[str(key)] = item
        return out
    if isinstance(value, list | tuple):
        return [json_safe(v, f"{where}[{i}]", urad=urad) for i, v in enumerate(value)]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, date):
        return value.isoformat()
    raise JsonValueError(where, value)


def from_json(cls, data, *, urad=False):
    """A dataclass from a dict of its fields, as :func:`json_safe` wrote it.

    Each field is converted by its annotation: a nested dataclass is built
    the same way, a list becomes a tuple for a ``tuple`` field, ``int``,
    ``bool`` and ``float`` fields get those types, and None stays None where
    the annotation allows it. A ``float`` field that does not allow None
    reads None as ``inf``: the only non-finite number such a field holds
    (a run length never reached) was written as ``null``. Keys that are not
    fields are ignored; a field missing from ``data`` keeps its default.

    Parameters
    ----------
    cls : type
        The dataclass.
    data : Mapping
        Its fields by name.
    urad : bool
        Read ``*_rad*`` float fields from ``*_urad*`` keys in µrad.

    Returns
    -------
    object
        An instance of ``cls``.

    Raises
    ------
    KeyError
        Naming the key of a field without a default that ``data`` lacks.
    TypeError, ValueError
        When a value does not convert.
    """
    kw = {}
    for name, (kind, optional, required) in _field_types(cls).items():
        key = name
        scaled = urad and kind is float and "_rad" in name
        if scaled:
            key = name.replace("_rad", "_urad")
        if key not in data:
            if required:
                raise KeyError(key)
            continue
        value = data[key]
        if value is None and optional:
            kw[name] = None
        elif dataclasses.is_dataclass(kind):
            kw[name] = from_json(kind, value, urad=urad)
        elif kind is float:
            kw[name] = math.inf if value is None else float(value) * (URAD if scaled else 1.0)
        elif kind in (int, bool, tuple):
            kw[name] = kind(value)
        else:
            kw[name] = value
    return cls(**kw)


@functools.cache
def _field_types(cls):
    """Per field of ``cls``: its type, whether it allows None, whether it has no default."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        kind = hints[f.name]
        args = typing.get_args(kind) if isinstance(kind, types.UnionType) else ()
        optional = type(None) in args
        if optional:
            kind = next(a for a in args if a is not type(None))
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        out[f.name] = (kind, optional, required)
    return out
