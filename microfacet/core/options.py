"""Typed options: frozen dataclasses whose fields carry their default, help, unit and valid
values, so that validation, the command line and the docs follow from one declaration.

A section of options is a frozen dataclass deriving from :class:`Options`; each field is
declared with :func:`option`. Constructing a section validates it (once, at the boundary): a
bad value raises :class:`~microfacet.core.errors.InputError` naming the field's path
(``roi.size_px`` inside a tree). Sections nest: a field whose default is a section is a
sub-section, and :meth:`Options.from_dict` / :meth:`Options.to_dict` round-trip the tree
through plain dicts (``summary.json`` records them).

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Roi(Options):
...     size_px: int = option(255, help="ROI side (seed: 255 px)", unit="px", low=8,
...                           cli=True)
>>> Roi().size_px, Roi(size_px=64).to_dict()
(255, {'size_px': 64})
>>> try:
...     Roi(size_px=4)
... except InputError as exc:
...     print(exc)
size_px: must be >= 8, got 4
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import MISSING, dataclass, field, fields

from .errors import InputError

__all__ = ["OptionField", "Options", "option", "option_fields"]


def option(default, *, help: str, unit: str = "", low=None, high=None,
           low_exclusive: bool = False, choices=None, kind=None, check=None, cli: bool = False,
           flag: str | None = None, metavar: str | None = None, cli_kwargs: dict | None = None):
    """A dataclass field of an :class:`Options` section.

    Parameters
    ----------
    default
        The one default of the option (a section for a sub-section).
    help : str
        One line for the command line's help and the docs.
    unit : str
        Unit of the value (``"px"``, ``"nm"``, ``"ΔE00"``).
    low, high : float, optional
        Inclusive bounds of a number (``low_exclusive``: ``> low``).
    choices : tuple, optional
        The allowed values.
    kind : type, optional
        The value's type when the default does not show it (a default of None); ``tuple``
        for a ``(low, high)`` pair.
    check : callable, optional
        ``check(value) -> str | None``: a reason when the value is invalid.
    cli : bool
        The command line offers this option (``--<prefix><name>``, dashes for underscores;
        the section's ``CLI_PREFIX`` in front).
    flag : str, optional
        The command-line flag when it differs from that rule.
    metavar : str, optional
    cli_kwargs : dict, optional
        More keyword arguments of ``argparse.add_argument`` (``nargs``, ``const``) for an option
        the usual rule (``type`` from the default) does not fit.
    """
    meta = dict(help=help, unit=unit, low=low, high=high, low_exclusive=low_exclusive,
                choices=None if choices is None else tuple(choices), kind=kind, check=check,
                cli=cli or flag is not None, flag=flag, metavar=metavar,
                cli_kwargs=dict(cli_kwargs or {}))
    if isinstance(default, Options):
        return field(default_factory=lambda: default, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class OptionField:
    """One leaf option of a tree: its dotted ``path`` (``"roi.size_px"``), its dataclass
    ``field``, the section class that declares it, and its command-line flag (None when the
    command line does not offer it)."""

    path: str
    field: dataclasses.Field
    section: type
    flag: str | None

    @property
    def default(self):
        return self.field.default

    @property
    def help(self) -> str:
        return self.field.metadata.get("help", "")

    @property
    def unit(self) -> str:
        return self.field.metadata.get("unit", "")

    @property
    def kind(self):
        k = self.field.metadata.get("kind")
        return k if k is not None else type(self.field.default)


def _default_of(f):
    return f.default_factory() if f.default is MISSING else f.default


def option_fields(cls, prefix: str = "") -> Iterator[OptionField]:
    """Every leaf option of the section class ``cls`` (sub-sections walked), in order."""
    for f in fields(cls):
        default = _default_of(f)
        path = f"{prefix}{f.name}"
        if isinstance(default, Options):
            yield from option_fields(type(default), prefix=f"{path}.")
            continue
        flag = None
        if f.metadata.get("cli"):
            flag = f.metadata.get("flag") or "--" + (cls.CLI_PREFIX + f.name).replace("_", "-")
        yield OptionField(path, f, cls, flag)


def _check_value(name: str, value, meta: dict, default) -> str | None:
    """The reason ``value`` is invalid for the field (None when it is valid)."""
    if value is None:
        return None if default is None else "must be given, got None"
    choices = meta.get("choices")
    if choices is not None and value not in choices:
        return f"must be one of {', '.join(map(str, choices))}, got {value!r}"
    low, high = meta.get("low"), meta.get("high")
    if low is not None or high is not None:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
                value):
            return f"must be a finite number, got {value!r}"
        if low is not None and (value <= low if meta.get("low_exclusive") else value < low):
            return f"must be {'>' if meta.get('low_exclusive') else '>='} {low:g}, got {value!r}"
        if high is not None and value > high:
            return f"must be <= {high:g}, got {value!r}"
        if (isinstance(default, int) and not isinstance(default, bool)
                and isinstance(value, float) and not value.is_integer()):
            return f"must be a whole number, got {value!r}"
    check: Callable | None = meta.get("check")
    return check(value) if check is not None else None


@dataclass(frozen=True)
class Options:
    """Base of a section of options (a frozen dataclass of :func:`option` fields).

    ``CLI_PREFIX`` is put in front of the command-line flags of its fields (``"roi-"``:
    ``size_px`` → ``--roi-size-px``).
    """

    CLI_PREFIX = ""

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            default = _default_of(f)
            if isinstance(default, Options):
                if isinstance(value, dict):
                    try:
                        value = type(default).from_dict(value)
                    except InputError as exc:
                        raise _with_prefix(exc, f"{f.name}.") from None
                    object.__setattr__(self, f.name, value)
                elif not isinstance(value, type(default)):
                    raise InputError(f"must be a section of options (a mapping), got "
                                     f"{value!r}", param=f.name)
                continue
            if isinstance(value, list) and f.metadata.get("kind") is tuple:
                object.__setattr__(self, f.name, value := tuple(value))
            reason = _check_value(f.name, value, f.metadata, _default_of(f))
            if reason is not None:
                raise InputError(reason, param=f.name)

    @classmethod
    def from_dict(cls, data: dict | None, *, where: str = ""):
        """The section from a (nested) dict of its fields; unknown keys are an InputError
        naming them, absent keys take their defaults."""
        data = dict(data or {})
        names = {f.name: f for f in fields(cls)}
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise InputError(f"unknown option(s) {', '.join(unknown)}; known: "
                             f"{', '.join(names)}", param=where.rstrip(".") or None)
        kw = {}
        for name, value in data.items():
            sub = _default_of(names[name])
            try:
                kw[name] = (type(sub).from_dict(value, where=f"{where}{name}.")
                            if isinstance(sub, Options) and isinstance(value, dict) else value)
            except InputError as exc:
                raise _with_prefix(exc, where) from None
        try:
            return cls(**kw)
        except InputError as exc:
            raise _with_prefix(exc, where) from None

    def to_dict(self) -> dict:
        """The section as a nested dict of plain values (tuples as lists)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = (v.to_dict() if isinstance(v, Options)
                           else list(v) if isinstance(v, tuple) else v)
        return out

    def replace(self, **changes):
        """A copy with ``changes``; a sub-section may be given as a dict of its changes
        (``options.replace(roi={"size_px": 128})``)."""
        kw = {}
        known = {f.name for f in fields(self)}
        for name, value in changes.items():
            if name not in known:
                raise InputError(f"unknown option; known: {', '.join(sorted(known))}",
                                 param=name)
            cur = getattr(self, name)
            try:
                kw[name] = cur.replace(**value) if isinstance(cur, Options) and isinstance(
                    value, dict) else value
            except InputError as exc:
                raise _with_prefix(exc, f"{name}.") from None
        try:
            return dataclasses.replace(self, **kw)
        except TypeError as exc:
            raise InputError(str(exc)) from None

    def flat(self) -> dict:
        """``{dotted path: value}`` of every leaf option (for comparisons and tables)."""
        out = {}
        for k, v in self.to_dict().items():
            if isinstance(v, dict):
                out.update({f"{k}.{kk}": vv for kk, vv in
                            type(getattr(self, k)).flat(getattr(self, k)).items()})
            else:
                out[k] = v
        return out


def _with_prefix(exc: InputError, where: str) -> InputError:
    param = f"{where}{exc.param}" if exc.param else (where.rstrip(".") or None)
    return InputError(exc.raw_reason, param=param)
