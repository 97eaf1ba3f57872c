"""The checks at the boundary: every argument a user hands the physics API or an env goes
through one of these functions once, where it enters, and a bad one is refused with a
sentence that names it: ``"<name> must be ..., got ..."``.

* :func:`real_array` -- an array of real numbers (integers or floats; not booleans, complex
  numbers, strings, objects or masked arrays) of a given shape, optionally finite, integer or
  within a range; torch tensors are read through their values (a tensor on the ``meta``
  device, which has none, is refused);
* :func:`finite_number` -- one real number (not a boolean or a string), finite, in a range;
* :func:`integer` -- one integer (``int`` or a NumPy integer; not a boolean, not a float such as
  ``2.0`` or ``inf``), in a range;
* :func:`boolean` -- ``True`` or ``False`` (``"no"`` is not False);
* :func:`one_of` -- one of a few named choices;
* :func:`generator` -- a ``numpy.random.Generator``.

Every refusal is a :class:`ContractError`, both a ``ValueError`` and a ``TypeError``, so that
callers catching either (the envs' conventions differ) see it. Pure Python and NumPy: the
physics layer imports no torch, and the TorchRL env hands its tensors to :func:`real_array`,
which reads them by their ``detach``/``cpu``/``numpy`` methods.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["ContractError", "boolean", "finite_number", "generator", "integer", "one_of", "real_array", "show"]


class ContractError(ValueError, TypeError):
    """An argument that breaks its contract (wrong type, shape, dtype or range)."""


def show(x, limit: int = 80) -> str:
    """A short ``repr`` of ``x`` for a message (a 400-digit integer or a big array is cut)."""
    if isinstance(x, np.ndarray) and x.size > 8:
        text = f"array of shape {x.shape} and dtype {x.dtype}"
    else:
        try:
            text = repr(x)
        except Exception:  # noqa: BLE001 - a repr that fails must not hide the real message
            text = f"<{type(x).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


# ----------------------------------------------------------------------------- scalars


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def _range_text(lo, hi, lo_open: bool, integral: bool = False) -> str:
    fmt = (lambda v: f"{v:,}") if integral else (lambda v: f"{v:g}")
    if lo is not None and hi is not None:
        return f" in {'(' if lo_open else '['}{fmt(lo)}, {fmt(hi)}]"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {fmt(lo)}"
    if hi is not None:
        return f" <= {fmt(hi)}"
    return ""


def finite_number(x, name: str, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
                  allow_inf: bool = False, what: str | None = None, note: str | None = None) -> float:
    """``x`` as a float, or a :class:`ContractError`: ``x`` must be a real number (``int``,
    ``float`` or a NumPy number; not a boolean, a string or a complex number), finite (or
    ``+inf`` with ``allow_inf``), at least ``lo`` (above it with ``lo_open``) and at most
    ``hi``. ``what`` replaces the description in the message ("a finite number >= 0"); past
    ``hi`` the message reads "must be at most hi (note)" when a ``note`` is given."""
    what = what or f"a finite number{_range_text(lo, hi, lo_open)}"
    if not _is_real(x):
        hint = " (a boolean is not a number)" if isinstance(x, (bool, np.bool_)) else ""
        raise ContractError(f"{name} must be {what}, got {show(x)}{hint}")
    try:
        v = float(x)
    except OverflowError:
        raise ContractError(f"{name} must be {what}, got {show(x)} (too large for a float)") from None
    if allow_inf and v == math.inf:
        return v
    if not math.isfinite(v) or (lo is not None and (v < lo or (lo_open and v == lo))):
        raise ContractError(f"{name} must be {what}, got {show(x)}")
    if hi is not None and v > hi:
        if note is not None:
            raise ContractError(f"{name} must be at most {hi:g} ({note}), got {show(x)}")
        raise ContractError(f"{name} must be {what}, got {show(x)}")
    return v


def integer(x, name: str, lo: int | None = None, hi: int | None = None, *, what: str | None = None) -> int:
    """``x`` as an ``int``, or a :class:`ContractError`: ``x`` must be an integer (``int`` or a
    NumPy integer; booleans are not integers, and neither are floats, ``2.0`` or ``inf``
    included) in [lo, hi]."""
    what = what or f"an integer{_range_text(lo, hi, False, integral=True)}"
    if isinstance(x, (bool, np.bool_)):
        raise ContractError(f"{name} must be {what}, got {x!r} (a boolean is not an integer)")
    if not isinstance(x, (int, np.integer)):
        raise ContractError(f"{name} must be {what}, got {show(x)} ({type(x).__name__}, not an integer)")
    v = int(x)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ContractError(f"{name} must be {what}, got {show(v)}")
    return v


def boolean(x, name: str) -> bool:
    """``x`` as a ``bool``, or a :class:`ContractError`: ``x`` must be ``True`` or ``False``
    (a Python or NumPy boolean: ``bool("no")`` would be True, ``1`` is an integer)."""
    if not isinstance(x, (bool, np.bool_)):
        raise ContractError(f"{name} must be True or False, got {show(x)}")
    return bool(x)


def one_of(x, name: str, choices):
    """The choice ``x`` names (one of ``choices``: strings, or ``None``), or a
    :class:`ContractError` listing them."""
    for c in choices:
        if x is c or (isinstance(c, str) and isinstance(x, str) and x == c):
            return c
    raise ContractError(f"{name} must be one of {tuple(choices)!r}, got {show(x)}")


def generator(x, name: str = "rng") -> np.random.Generator:
    """``x`` if it is a ``numpy.random.Generator``, else a :class:`ContractError`."""
    if not isinstance(x, np.random.Generator):
        raise ContractError(f"{name} must be a numpy.random.Generator (numpy.random.default_rng(seed)), got {show(x)}")
    return x


# ----------------------------------------------------------------------------- arrays

_KIND_HINTS = {
    "b": " (booleans are not numbers)",
    "c": " (complex numbers: the imaginary part would be dropped)",
    "U": " (strings are not numbers)",
    "S": " (bytes are not numbers)",
    "O": " (objects are not numbers)",
}


def _values(x, name: str):
    """A tensor's values as a NumPy array (any object with ``detach`` and ``cpu``: a torch
    tensor, part of a graph or not, on any device it can be copied from); anything else as is."""
    if not (hasattr(x, "detach") and hasattr(x, "cpu") and hasattr(x, "numpy")):
        return x
    device = getattr(getattr(x, "device", None), "type", "cpu")
    if device == "meta":
        raise ContractError(f"{name} must hold values, got a tensor on the meta device (it has a shape but no data)")
    try:
        t = x.detach().cpu()
    except (RuntimeError, NotImplementedError) as err:
        raise ContractError(f"{name} must be a tensor whose values can be copied to the CPU, got one on {device}: {err}") from None
    if getattr(t, "is_complex", lambda: False)():
        raise ContractError(f"{name} must hold real numbers, got a tensor of dtype {t.dtype}{_KIND_HINTS['c']}")
    try:
        return t.numpy()
    except (TypeError, RuntimeError):  # a dtype NumPy lacks (bfloat16): its values as float32, exactly
        if t.is_floating_point():
            return t.float().numpy()
        raise ContractError(f"{name} must hold real numbers, got a tensor of dtype {t.dtype}") from None


def _shape_text(shapes) -> str:
    return " or ".join("(" + ", ".join("N" if d is None else str(d) for d in s) + ("," if len(s) == 1 else "") + ")"
                       for s in shapes)


def _fits(shape, pattern) -> bool:
    return len(shape) == len(pattern) and all(p is None or p == d for p, d in zip(pattern, shape))


def real_array(x, name: str, shape=None, *, integer: bool = False, finite: bool = False, lo: float | None = None,
               hi: float | None = None, note: str = "") -> np.ndarray:
    """``x`` as a float64 array (int64 with ``integer``), or a :class:`ContractError`.

    ``x`` must hold real numbers: a NumPy array, a (nested) list, a number or a torch tensor
    of integers or floats (with ``integer``: of integers only); booleans, complex numbers,
    strings, objects and masked arrays (``numpy.ma``: the masked entries would silently count
    as their hidden values) are refused. ``shape`` (optional) is one pattern or a list of
    patterns, tuples whose ``None`` entries match any size (``[(4,), (None, 4)]``); ``note``
    follows the shape in its message (" = (theta, p, a, b)"). ``finite``: no NaN or inf.
    ``lo``/``hi``: every entry in [lo, hi]. The conversion is NumPy's ``astype`` (float64
    input comes back as it is, the same bits)."""
    given = type(x).__name__
    if x is None:
        raise ContractError(f"{name} must be an array of real numbers, got None")
    if isinstance(x, np.ma.MaskedArray):
        raise ContractError(f"{name} must be a plain array of real numbers, got a masked array (numpy.ma): its masked "
                            f"entries would be used as their hidden values; pass numpy.ma.filled(x, value) or x.data")
    x = _values(x, name)
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError, RuntimeError, OverflowError) as err:
        raise ContractError(f"{name} must be an array of real numbers, got {given}: {err}") from None
    kinds = "iu" if integer else "iuf"
    if raw.dtype.kind not in kinds:
        want = "integers" if integer else "real numbers"
        raise ContractError(f"{name} must hold {want}, got {given} of dtype {raw.dtype}{_KIND_HINTS.get(raw.dtype.kind, '')}")
    if shape is not None:
        shapes = [shape] if isinstance(shape, tuple) else list(shape)
        if not any(_fits(raw.shape, s) for s in shapes):
            raise ContractError(f"{name} must have shape {_shape_text(shapes)}{note}; got shape {raw.shape}")
    arr = raw.astype(np.int64 if integer else np.float64, copy=False)
    if finite and not integer and not np.isfinite(arr).all():
        raise ContractError(f"{name} must hold finite numbers (of shape {_shape_text([arr.shape])}); got NaN or inf "
                            f"at {_where(~np.isfinite(arr))}")
    if lo is not None or hi is not None:
        bad = np.zeros(arr.shape, dtype=bool)
        if lo is not None:
            bad |= ~(arr >= lo)
        if hi is not None:
            bad |= ~(arr <= hi)
        if bad.any():
            first = (arr[tuple(np.argwhere(bad)[0])] if arr.ndim else arr[()]).item()
            raise ContractError(f"{name} must lie in [{'-inf' if lo is None else f'{lo:g}'}, "
                                f"{'inf' if hi is None else f'{hi:g}'}]; got {first!r} at {_where(bad)}")
    return arr


def _where(bad: np.ndarray) -> str:
    """Where a boolean mask is set, for a message: "index 2", or "row(s) [0, 3]" of a 2-D array."""
    if bad.ndim == 0:
        return "its value"
    if bad.ndim == 1:
        where = np.flatnonzero(bad)[:8].tolist()
        return f"index {where[0]}" if len(where) == 1 else f"indices {where}"
    rows = np.unique(np.argwhere(bad.reshape(bad.shape[0], -1))[:, 0])[:8].tolist()
    return f"row(s) {rows}"
