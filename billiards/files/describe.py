"""How a message about a file shows a value read from it without quoting it: :func:`described`
(what it is: "a negative integer", "a string" ...), :func:`shown_number`, :func:`shown_name`,
and the number tests the ledgers' shape checks share."""

from __future__ import annotations

import math
import re

def _int(x, low: int = 0) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= low


def _number(x, low: float | None = None) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        f = float(x)
    except OverflowError:  # an integer beyond any float
        return False
    return math.isfinite(f) and (low is None or f >= low)


_MISSING = object()


def described(x=_MISSING) -> str:
    """What a value read from a file is, without quoting it (a message about a file never
    repeats what the file holds): "nothing" (missing), "null", "a boolean", "a negative
    integer", "a fraction", "a string", "an array" ..."""
    if x is _MISSING:
        return "nothing"
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, int):
        if not _number(x):
            return "an integer beyond any float"
        return "a negative integer" if x < 0 else "an integer"
    if isinstance(x, float):
        if not math.isfinite(x):
            return "a non-finite number"
        return "a negative number" if x < 0 else "a number" if x.is_integer() else "a fraction"
    return {str: "a string", list: "an array", dict: "an object"}.get(type(x), f"a {type(x).__name__}")


def shown_number(x) -> str:
    """A value read from a file as a message shows it: a finite number as it is (a number is no
    secret), anything else :func:`described`."""
    return repr(x) if _number(x) else described(x)


_NAME = re.compile(r"[\w.:/+@-]{1,64}")
_IDENT = re.compile(r"[0-9a-f]{16}")


def shown_name(x) -> str:
    """A name read from a file (a player's) as a message shows it: itself when it is a short
    name (letters, digits, ``_ . : / + @ -``, at most 64), else :func:`described`."""
    return x if isinstance(x, str) and _NAME.fullmatch(x) else f"{described(x)} (no player's name)"


def _shown_ident(x) -> str:
    return repr(x) if isinstance(x, str) and _IDENT.fullmatch(x) else "an identity that is no 16-digit hash"
