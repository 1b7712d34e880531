"""Exception hierarchy owned by facebasis.

Every error a user can trigger with bad input derives from :class:`FacebasisError`, so a caller
can catch the toolkit's errors without catching programming errors. Messages name the file or
parameter, what was expected and what was found.

An error may carry these as structured fields (``what``, ``expected``, ``found``) in which the
library's parameters are written as ``{name}`` placeholders (``params``: placeholder -> the
parameter's library name). ``str(error)`` writes each by its library name
(``"iterations: expected >= 1, found 0"``); an application that knows its own name for a parameter
writes the same error with it (:meth:`FacebasisError.renamed`: the command line's
``"--iterations: expected >= 1, found 0"``), without parsing the message's text. A message that is
not of that form is a template with the same placeholders (``FacebasisError("... name it with
{neutral}", params={"neutral": "neutral"})``), and a hint or warning the library prints through a
caller's ``log`` is a :class:`NamedText`, renamed the same way (:func:`renamed_text`).
"""

from __future__ import annotations

import copy
import re

_PLACEHOLDER = re.compile(r"\{(\w+)\}")


def _fill(template, names: dict) -> str:
    return _PLACEHOLDER.sub(lambda m: names.get(m.group(1), m.group(0)), str(template))


def named_params(*texts) -> dict:
    """{placeholder: placeholder} of every ``{name}`` in ``texts``: the ``params`` of a label a caller
    gave (``what="{unit}"``), whose placeholders are the library's parameter names."""
    return {m.group(1): m.group(1) for t in texts for m in _PLACEHOLDER.finditer(str(t or ""))}


class NamedText(str):
    """A line the library prints (a hint, a warning) that names its parameters: a ``str`` written
    with their library names, whose :meth:`renamed` writes them by a caller's names (the flags).

    Parameters
    ----------
    template : the text with ``{name}`` placeholders
    params : {placeholder: library name}; default every placeholder as itself
    """

    def __new__(cls, template: str, params: dict | None = None):
        params = named_params(template) if params is None else dict(params)
        obj = super().__new__(cls, _fill(template, params))
        obj.template, obj.params = template, params
        return obj

    def renamed(self, names: dict) -> str:
        """The text with the parameters ``names`` knows written by those names."""
        return _fill(self.template, {**self.params, **{k: v for k, v in names.items() if k in self.params}})


def renamed_text(text, names: dict) -> str:
    """``text`` with its parameters written by ``names`` if it is a :class:`NamedText`, else itself."""
    return text.renamed(names) if isinstance(text, NamedText) else text


class FacebasisError(Exception):
    """Base class of every error raised on purpose by facebasis.

    Parameters
    ----------
    message : the whole message (an error without structured fields), or None to compose it from
        the fields as ``"{what}: expected {expected}, found {found}{note}"``
    what, expected, found, note : the structured fields (text; ``{name}`` placeholders for the
        parameters of ``params``)
    params : {placeholder: library name} of the parameters the fields mention; with ``message`` and
        no fields, ``message`` is a template with these placeholders
    """

    def __init__(self, message: str | None = None, *, what=None, expected=None, found=None, note: str = "",
                 params: dict | None = None):
        self.what, self.expected, self.found, self.note = what, expected, found, note
        self.params = dict(params or {})
        self.template = message if message is not None and what is None and self.params else None
        super().__init__(message if message is not None and self.template is None else self._compose({}))

    def _compose(self, names: dict) -> str:
        names = {**self.params, **{k: v for k, v in names.items() if k in self.params}}
        if self.template is not None:
            return _fill(self.template, names)
        return (f"{_fill(self.what, names)}: expected {_fill(self.expected, names)}, "
                f"found {_fill(self.found, names)}{_fill(self.note, names)}")

    def renamed(self, names: dict) -> "FacebasisError":
        """The same error with its parameters written by ``names`` ({library name: the caller's name},
        e.g. the command line's flags); itself if it has no structured fields or none of them is named."""
        if (self.what is None and self.template is None) or not set(names) & set(self.params):
            return self
        new = copy.copy(self)
        new.args = (self._compose(names),)
        return new


def parameter_error(name: str, expected, found, *, label: str | None = None, note: str = "",
                    cls: type | None = None) -> "FacebasisError":
    """An error about the library parameter ``name`` (written ``label``, default ``name``):
    ``"{label}: expected {expected}, found {found}{note}"``, an :class:`InputError` unless ``cls``."""
    return (cls or InputError)(what="{" + name + "}", expected=expected, found=found, note=note,
                               params={name: label or name})


def parse_mode(name: str, value, modes: tuple, default: str) -> str:
    """The mode ``value`` names, lower-cased and stripped (None: ``default``); anything else is a
    :func:`parameter_error` listing ``modes``."""
    if value is None:
        return default
    if not isinstance(value, str) or value.strip().lower() not in modes:
        raise parameter_error(name, f"one of {', '.join(modes)}", repr(value))
    return value.strip().lower()


class MeshError(FacebasisError):
    """A mesh is unreadable, malformed or geometrically unusable (NaN, degenerate, bad indices)."""


class TopologyError(MeshError):
    """Meshes that must share one topology do not (vertex count, faces)."""


class RigError(FacebasisError):
    """A rig folder or rig object is inconsistent (missing neutral, unknown shape names, ...)."""


class InputError(FacebasisError):
    """A parameter or input file has a wrong value (weights out of range, bad JSON, ...)."""


class SolverError(FacebasisError):
    """A numerical solver failed; the message carries the solver's own status."""

    def __init__(self, message: str, status: str | None = None):
        super().__init__(message)
        self.status = status
