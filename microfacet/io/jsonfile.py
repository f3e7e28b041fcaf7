"""Reading the JSON files users hand us (``stack.json``), strictly and in bounded memory.

* a UTF-8 byte-order mark (Windows editors write one) is accepted;
* a key given twice in one object is an error naming the key (``json`` keeps the last one
  silently, which reads a different file than the user sees);
* nesting deeper than Python's recursion limit, files over
  :data:`~microfacet.io.limits.MAX_JSON_BYTES` and integers of hundreds of digits are refused
  or read as out-of-range numbers, never a traceback;
* ``NaN`` and ``Infinity`` are read (the callers refuse them with the key's name).

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "s.json"
>>> _ = p.write_bytes(b'\\xef\\xbb\\xbf{"a": 1}')
>>> read_json(p)
{'a': 1}
>>> _ = p.write_text('{"a": 1, "a": 2}')
>>> try:
...     read_json(p)
... except InputError as exc:
...     print(str(exc).split(": ", 1)[1])
key 'a' is given twice (the second would silently win)
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from .limits import MAX_JSON_BYTES, check_file_size

__all__ = ["json_safe", "parse_json", "read_json"]


def _pairs(pairs):
    out = {}
    for key, value in pairs:
        if key in out:
            raise _Duplicate(key)
        out[key] = value
    return out


class _Duplicate(Exception):
    pass


def _int(text: str):
    # 400-digit integers become an out-of-range float (inf) that callers refuse by name
    return int(text) if len(text) <= 18 else float(text)


def read_json(path, *, max_bytes: int = MAX_JSON_BYTES):
    """Parse the JSON file ``path`` (see the module notes).

    Raises
    ------
    InputError
        Naming the file: unreadable, too large, not UTF-8, invalid JSON (with line and
        column), a duplicate key, or nested too deeply.
    """
    path = Path(path)
    shown = one_line(path)
    try:
        check_file_size(path, max_bytes, shown)
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise InputError(f"{shown}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{shown}: not UTF-8 text (byte {exc.start})") from None
    return parse_json(text, shown)


def parse_json(text: str, shown: str):
    """``text`` parsed as strictly as :func:`read_json` reads a file; errors name ``shown``
    (the file, or the archive member, the text came from).

    >>> parse_json('{"a": [1, 2]}', "x.json")
    {'a': [1, 2]}
    """
    try:
        return json.loads(text, object_pairs_hook=_pairs, parse_int=_int)
    except _Duplicate as exc:
        raise InputError(f"{shown}: key {exc.args[0]!r} is given twice (the second would "
                         f"silently win)") from None
    except RecursionError:
        raise InputError(f"{shown}: nested too deeply to be a microfacet file") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{shown}: invalid JSON ({exc.msg} at line {exc.lineno} column "
                         f"{exc.colno})") from None


def json_safe(x):
    """``x`` made JSON-safe: NaN and ±inf → None, numpy scalars and arrays → Python (the one
    sanitiser of everything the package writes as JSON).

    >>> import numpy as np
    >>> json_safe({"a": np.float32(1.5), "b": [np.nan, np.int64(2)], "c": np.bool_(True)})
    {'a': 1.5, 'b': [None, 2], 'c': True}
    """
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    return x
