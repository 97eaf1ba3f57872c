"""What to install when a module the benchmark needs is missing: the requirement of the
distribution (``sagu-bench``) that provides it, read from the installed distribution's metadata
(or, in a source checkout that is not installed, from its ``pyproject.toml``)."""

from __future__ import annotations

import re

DISTRIBUTION = "sagu-bench"
# distributions whose import name is spelled otherwise (normalised: lower case, "_" for "-" and ".")
IMPORT_NAMES = {"hydra_core": "hydra", "pillow": "pil", "pytest_xdist": "xdist"}


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def requirements() -> list[tuple[str, str, str | None]]:
    """The distribution's requirements as (import name, requirement, extra or None for a core
    dependency); empty where neither the metadata nor a ``pyproject.toml`` is found."""
    from importlib.metadata import PackageNotFoundError, requires

    try:
        found = [(r.split(";")[0].strip(), re.search(r"extra\s*==\s*[\"']([^\"']+)[\"']", r)) for r in requires(DISTRIBUTION) or []]
        reqs = [(req, extra.group(1) if extra else None) for req, extra in found]
    except PackageNotFoundError:
        reqs = _pyproject_requirements()
    out = []
    for req, extra in reqs:
        name = re.match(r"[A-Za-z0-9][A-Za-z0-9._-]*", req)
        if name:
            dist = _norm(name.group(0))
            out.append((IMPORT_NAMES.get(dist, dist), req, extra))
    return out


def _pyproject_requirements() -> list[tuple[str, str | None]]:
    import tomllib

    from billiards.files import ROOT

    path = ROOT / "pyproject.toml"
    if not path.is_file():
        return []
    project = tomllib.loads(path.read_text()).get("project", {})
    return [(r, None) for r in project.get("dependencies", [])] + \
        [(r, extra) for extra, reqs in project.get("optional-dependencies", {}).items() for r in reqs]


def import_name(module: str) -> str:
    """The part of a dotted module name that names its distribution (``hydra_plugins.X``: X)."""
    parts = module.split(".")
    return parts[1] if parts[0] == "hydra_plugins" and len(parts) > 1 else parts[0]


def install_hint(module: str) -> str:
    """How to install ``module``: ``pip install "sagu-bench[<extra>]"`` for a module an extra
    provides, the pinned requirement for a dependency of the distribution itself (a broken
    install), else ``pip install <module>``."""
    key = _norm(import_name(module))
    found = [(req, extra) for name, req, extra in requirements() if name == key]
    core = [req for req, extra in found if extra is None]
    if core:
        return f'pip install "{core[0]}" (a dependency of {DISTRIBUTION}: the install is incomplete)'
    extras = [extra for _, extra in found]
    if extras:
        extra = next((e for e in extras if e != "test"), extras[0])
        return f'pip install "{DISTRIBUTION}[{extra}]"'
    return f"pip install {import_name(module)}"


__all__ = ["DISTRIBUTION", "import_name", "install_hint", "requirements"]
