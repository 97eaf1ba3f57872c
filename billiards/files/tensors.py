"""The small ``torch.save`` files with a format tag (exported policies, shot rankers, reward
models): :func:`save_tagged` seals one, :func:`load_tagged` turns every way such a file can be
bad into one clear error; and the checks of what such a file means (:func:`tensor_problem`,
:func:`key_problem`, :func:`plain_data_problem`, :func:`shape_problem`). Torch is imported
lazily."""

from __future__ import annotations

from pathlib import Path

from .atomic import atomic_write_bytes
from .seals import SEAL_KEY, non_finite_entry, payload_digest

# ----------------------------------------------------------------------------- a file's meaning
#
# A seal proves a file is what was written, not that it makes sense: each model file kind checks
# its content in one place after the seal (``check_policy``, ``check_checkpoint``,
# ``TaggedMLP.check`` for rankers and table values, ``check_reward_model``), with these helpers.
# Each returns what is wrong, one phrase naming the entry, or None; the caller raises its own
# error naming the file.

MAX_NESTING = 64  # how deep stored plain data may nest (a deeper one is damage, and would exhaust the stack)


def tensor_problem(tree, where: str, floats_only: bool = True) -> str | None:
    """The first tensor (or NumPy array) in ``tree`` (dicts, lists and tuples at any depth) that
    is complex, or holds NaN or an infinity, or (``floats_only``) is not of a real
    floating-point dtype, as ``"<where>.<key>: ..."``."""
    import numpy as np
    import torch

    def visit(x, name: str, depth: int) -> str | None:
        if depth > MAX_NESTING:
            return f"{name}: nested deeper than {MAX_NESTING} levels"
        if torch.is_tensor(x):
            complex_, floating = x.is_complex(), x.is_floating_point()
            finite = lambda: bool(torch.isfinite(x).all())  # noqa: E731
        elif isinstance(x, np.ndarray):
            complex_, floating = x.dtype.kind == "c", x.dtype.kind == "f"
            finite = lambda: bool(np.isfinite(x).all())  # noqa: E731
        else:
            complex_ = floating = None
        if complex_ is not None:
            if complex_ or (floats_only and not floating):
                return f"{name}: a tensor of dtype {x.dtype}, not of real floating-point numbers"
            if floating and not finite():
                return f"{name}: holds NaN or an infinity"
            return None
        items = x.items() if isinstance(x, dict) else enumerate(x) if isinstance(x, (list, tuple)) else ()
        for k, v in items:
            if (bad := visit(v, f"{name}.{k}", depth + 1)) is not None:
                return bad
        return None

    return visit(tree, where, 0)


def key_problem(payload, spec: dict, where: str = "") -> str | None:
    """What is wrong with ``payload``'s keys: ``spec`` maps each required key to its type (or a
    tuple of types); a key missing or of another type (a boolean is no number) is named."""
    say = f"{where}: " if where else ""
    if not isinstance(payload, dict):
        return f"{say}a {type(payload).__name__}, not a mapping"
    for key, kind in spec.items():
        if key not in payload:
            return f"{say}'{key}' is missing"
        value = payload[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            names = " or ".join(k.__name__ if k is not type(None) else "None" for k in kinds)
            return f"{say}'{key}' is a {type(value).__name__}, not a {names}"
    return None


def plain_data_problem(value, where: str) -> str | None:
    """What keeps ``value`` from being plain data (a stored config, metadata): anything but
    dicts with string keys, lists, strings, numbers, booleans and None, nesting past
    :data:`MAX_NESTING`, or a string holding an interpolation (``${``: a stored config is what
    was resolved when it was written; ``${oc.env:HOME}`` would read this machine's environment)."""

    def visit(x, name: str, depth: int) -> str | None:
        if depth > MAX_NESTING:
            return f"{name}: nested deeper than {MAX_NESTING} levels"
        if isinstance(x, str):
            return f"{name}={x[:80]!r}: an interpolation ('${{'); a stored config holds values only" if "${" in x else None
        if x is None or isinstance(x, (bool, int, float)):
            return None
        if isinstance(x, dict):
            for k, v in x.items():
                if not isinstance(k, str):
                    return f"{name}: a key of type {type(k).__name__} (keys are strings)"
                if "${" in k:
                    return f"{name}: the key {k[:80]!r} holds an interpolation"
                if (bad := visit(v, f"{name}.{k}", depth + 1)) is not None:
                    return bad
            return None
        if isinstance(x, (list, tuple)):
            for i, v in enumerate(x):
                if (bad := visit(v, f"{name}[{i}]", depth + 1)) is not None:
                    return bad
            return None
        return f"{name}: a {type(x).__name__}, not plain data"

    return visit(value, where, 0)


def shape_problem(expected: dict, got, where: str) -> str | None:
    """What is wrong with the tensors ``got`` (a state dict) against ``expected`` (name ->
    shape, from the network the file's own config builds): a name missing or extra, a value
    that is no tensor, a shape that differs."""
    import torch

    if not isinstance(got, dict):
        return f"{where}: a {type(got).__name__}, not a mapping of tensors"
    missing = [k for k in expected if k not in got]
    extra = [str(k) for k in got if k not in expected]
    if missing or extra:
        say = [f"lacks {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}" if missing else "",
               f"holds {', '.join(extra[:4])}{' ...' if len(extra) > 4 else ''} that it does not have" if extra else ""]
        return f"{where}: not the network its config describes: it " + " and ".join(s for s in say if s)
    for k, shape in expected.items():
        v = got[k]
        if not torch.is_tensor(v):
            return f"{where}.{k}: a {type(v).__name__}, not a tensor"
        if tuple(v.shape) != tuple(shape):
            return f"{where}.{k}: shape {tuple(v.shape)}, but the network its config describes has {tuple(shape)}"
    return None


def save_tagged(path, payload: dict) -> Path:
    """Write a tagged payload (``"format"`` set by the caller) with its checksum
    (:func:`payload_digest`), atomically; :func:`load_tagged` checks both."""
    import io

    import torch

    buf = io.BytesIO()
    torch.save({**payload, SEAL_KEY: payload_digest(payload)}, buf)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, buf.getvalue())


def load_tagged(path, tag: str, error: type[Exception], what: str) -> dict:
    """``torch.load`` (tensors and plain containers only: nothing in the file is executed) of a
    dict whose ``"format"`` is ``tag``, sealed by :func:`save_tagged`; raises ``error`` naming
    the path and ``what`` was expected if the file is missing, empty, unreadable, of another
    format, without its checksum or not matching it (a flipped bit), or holds a NaN or an
    infinity. The loaders check the shapes their layout declares."""
    payload = _load_tagged_unchecked(path, tag, error, what)
    if SEAL_KEY not in payload:
        raise error(f"{what} file {path} carries no checksum: python -m billiards.compat seal {path} checks its "
                    f"contents and seals it")
    if payload[SEAL_KEY] != payload_digest(payload):
        raise error(f"{what} file {path} is damaged: its contents do not match its sha256 checksum")
    if (bad := non_finite_entry(payload)) is not None:
        raise error(f"{what} file {path} holds non-finite values (NaN or inf) in {bad}")
    return payload


def _load_tagged_unchecked(path, tag: str, error: type[Exception], what: str) -> dict:
    import torch

    path = Path(path)
    if not path.is_file():
        raise error(f"{what} file {path} does not exist")
    if path.stat().st_size == 0:
        raise error(f"{what} file {path} is empty")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for a corrupt file
        raise error(f"{what} file {path} is corrupt or not a torch file ({type(err).__name__}: {err})") from None
    if not isinstance(payload, dict) or payload.get("format") != tag:
        raise error(f"{path} is not a {what} file (expected format tag {tag!r})")
    return payload
