"""The seals (sha256 checksums) that sealed files and ledger records carry under
:data:`SEAL_KEY`: :func:`payload_digest` over a tagged payload's tensors and values,
:func:`record_digest` and :func:`sealed_record` over a JSON record, and
:func:`non_finite_entry`, the first NaN or infinity of a payload."""

from __future__ import annotations

SEAL_KEY = "sha256"  # the checksum entry of a sealed (tagged) file


def payload_digest(payload) -> str:
    """SHA-256 over a payload's content in a canonical order: every key (sorted), tensor (dtype,
    shape, bytes), array and plain value, except the top-level :data:`SEAL_KEY` itself. The same
    content gives the same digest however ``torch.save`` lays it out."""
    import hashlib
    import json

    import numpy as np
    import torch

    h = hashlib.sha256()

    def feed(x) -> None:
        if isinstance(x, dict):
            h.update(b"d%d" % len(x))
            for k in sorted(x, key=str):
                feed(str(k))
                feed(x[k])
        elif isinstance(x, (list, tuple)):
            h.update(b"l%d" % len(x))
            for v in x:
                feed(v)
        elif torch.is_tensor(x):
            t = x.detach().cpu().contiguous()
            h.update(f"t{t.dtype}{tuple(t.shape)}".encode())
            h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
        elif isinstance(x, np.ndarray):
            a = np.ascontiguousarray(x)
            h.update(f"a{a.dtype}{a.shape}".encode() + a.tobytes())
        else:
            h.update(("v" + json.dumps(x, sort_keys=True, default=repr)).encode())

    feed({k: v for k, v in payload.items() if k != SEAL_KEY})
    return h.hexdigest()


def non_finite_entry(payload, prefix: str = "") -> str | None:
    """The first entry of ``payload`` holding a NaN or an infinity (floating tensors and arrays)."""
    import numpy as np
    import torch

    items = payload.items() if isinstance(payload, dict) else enumerate(payload) if isinstance(payload, (list, tuple)) else ()
    for k, v in items:
        name = f"{prefix}{k}"
        if torch.is_tensor(v) and v.is_floating_point() and v.numel() and not bool(torch.isfinite(v).all()):
            return name
        if isinstance(v, np.ndarray) and v.dtype.kind == "f" and not np.isfinite(v).all():
            return name
        if isinstance(v, (dict, list, tuple)) and (bad := non_finite_entry(v, f"{name}.")):
            return bad
    return None


def record_digest(record: dict) -> str:
    """SHA-256 of a JSON record (its keys sorted), without its own :data:`SEAL_KEY` entry: the
    checksum each line of an append-only ledger and each whole JSON ledger carries."""
    import hashlib
    import json

    body = {k: v for k, v in record.items() if k != SEAL_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def sealed_record(record: dict) -> dict:
    """The record with its checksum (:func:`record_digest`) under :data:`SEAL_KEY`."""
    return {**{k: v for k, v in record.items() if k != SEAL_KEY}, SEAL_KEY: record_digest(record)}
