"""Exception types for user errors."""

from __future__ import annotations

import re

__all__ = ["InputError", "one_line", "plain_params", "render_params"]

_PARAM_REF = re.compile(r"`([A-Za-z_][A-Za-z0-9_.]*)`")


def option_name(param: str, flags=None) -> str:
    """The command-line option of a library parameter: the flag ``flags`` gives it (a mapping
    from dotted option paths such as ``roi.size_px`` to flags, from the options' metadata),
    else dashes for underscores: ``out`` → ``--out``, ``z_step_um`` → ``--z-step-um``.

    >>> option_name("z_step_um"), option_name("roi.size_px", {"roi.size_px": "--roi-size-px"})
    ('--z-step-um', '--roi-size-px')
    """
    if flags and param in flags:
        return flags[param]
    return "--" + param.replace("_", "-").replace(".", "-")


class InputError(ValueError):
    """Bad user input (a file, key, parameter or the environment); the message names it.

    Parameters
    ----------
    reason : str
        What is wrong, naming the file or key where there is one.
    param : str, optional
        The library parameter at fault (``"out"``, ``"thickness_range_nm"``, ...). ``str()``
        then reads ``"param: reason"``; the command line shows the option instead
        (``--out: reason``). Other parameters named in ``reason`` are written in backticks
        (```overwrite```) and shown the same way.

    Examples
    --------
    >>> e = InputError("already exists; `overwrite` replaces it", param="out")
    >>> str(e)
    'out: already exists; overwrite replaces it'
    >>> e.cli_message()
    '--out: already exists; --overwrite replaces it'

    The command line reports it as one line and exits with status 2.
    """

    def __init__(self, reason: str, *, param: str | None = None):
        self.raw_reason = str(reason)
        self.param = param
        self.reason = _PARAM_REF.sub(r"\1", self.raw_reason)
        super().__init__(f"{param}: {self.reason}" if param else self.reason)

    def cli_message(self, flags=None) -> str:
        """The message with parameter names replaced by their command-line options
        (``flags``: see :func:`option_name`)."""
        reason = render_params(self.raw_reason, flags)
        return f"{option_name(self.param, flags)}: {reason}" if self.param else reason


def render_params(text: str, flags=None) -> str:
    """``text`` with the parameter names in backticks shown as command-line options.

    >>> render_params("narrow `optics.thickness_range_nm`", {"optics.thickness_range_nm":
    ...                                                      "--thickness-range-nm"})
    'narrow --thickness-range-nm'
    """
    return _PARAM_REF.sub(lambda m: option_name(m.group(1), flags), str(text))


def plain_params(text: str) -> str:
    """``text`` with the backticks around parameter names removed (for Python users).

    >>> plain_params("narrow `optics.thickness_range_nm`")
    'narrow optics.thickness_range_nm'
    """
    return _PARAM_REF.sub(r"\1", str(text))


def one_line(text: str) -> str:
    """``text`` with control characters (newlines in a file name, ...) escaped, so that a
    message stays on one line.

    >>> one_line("a\\nb\\x00c")
    'a\\\\nb\\\\x00c'
    """
    out = []
    for ch in str(text):
        if ch == "\t":
            out.append(" ")
        elif ord(ch) < 32 or ord(ch) == 127:
            out.append(repr(ch)[1:-1])
        else:
            out.append(ch)
    return "".join(out)
