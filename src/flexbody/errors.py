"""The exceptions that tell a user's mistake from a failure and from a bug.

The command line maps them to exit codes: :class:`InputError` (a bad scene, option or
output folder) exits 2 with its message and nothing else; a failed simulation exits 1
and says why; any other exception is a bug in flexbody and prints its traceback.
"""

from __future__ import annotations

import reprlib

#: How long a value may be when it is quoted in a message (longer ones end in "…").
SHOWN_LENGTH = 80

_repr = reprlib.Repr()
_repr.maxlevel, _repr.maxlist, _repr.maxtuple, _repr.maxdict = 3, 8, 8, 6
_repr.maxstring, _repr.maxlong, _repr.maxother = SHOWN_LENGTH, 40, SHOWN_LENGTH


class InputError(ValueError):
    """A user's mistake in a scene, an option or an output path (the CLI exits 2).

    A subclass of ``ValueError``, so code that catches ``ValueError`` keeps working.
    """


def shown(value: object) -> str:
    """``repr(value)`` cut to at most :data:`SHOWN_LENGTH` characters, for messages.

    Long lists, deep nesting and huge integers are abbreviated (a 20 000-element list
    or a 400-digit number must not flood the terminal).
    """
    try:
        text = _repr.repr(value)
    except RecursionError:  # pragma: no cover - reprlib already stops at maxlevel
        text = f"<{type(value).__name__}>"
    return text if len(text) <= SHOWN_LENGTH else text[: SHOWN_LENGTH - 1] + "…"
