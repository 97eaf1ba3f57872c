#!/usr/bin/env bash
# Create a separate virtual environment holding pooltool-billiards 0.6.0, used only as a
# reference oracle (benchmarks/pooltool_oracle.py). Idempotent: re-running it on a working
# venv only re-checks it.
#
#   bash benchmarks/setup_pooltool.sh            # venv at .venv-pooltool in the repository
#   POOLTOOL_VENV=/some/dir bash benchmarks/setup_pooltool.sh
#   PYTHON=python3.11 bash benchmarks/setup_pooltool.sh
#
# Why not a plain `pip install pooltool-billiards==0.6.0`: its wheel metadata requires
# panda3d==1.11.0.dev3702 (a dev build not on PyPI) on Linux, and llvmlite<0.46. So we
# install its other Requires-Dist entries ourselves, with panda3d==1.10.16 (which provides
# everything the physics path needs) and numba 0.62.x / llvmlite 0.45.x (the newest pair
# that satisfies llvmlite<0.46 and has Python 3.11 wheels), then pooltool with --no-deps.
# torch is never installed here.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/.." && pwd)"
VENV="${POOLTOOL_VENV:-$REPO/.venv-pooltool}"
PYTHON="${PYTHON:-python3}"
POOLTOOL_VERSION="0.6.0"

# Requires-Dist of pooltool_billiards-0.6.0-py3-none-any.whl (read from its METADATA), with
# the panda3d pin replaced as explained above, each pinned to the exact release that was
# installed and verified (benchmarks/POOLTOOL_NOTES.md) so the oracle stays reproducible.
# The wheel's own ranges are in the comments. numpy stays < 2.4 for numba 0.62.
DEPS=(
  "panda3d==1.10.16"          # wheel: ==1.11.0.dev3702 (not on PyPI)
  "panda3d-gltf==1.3.0"       # >=1.2.0
  "panda3d-simplepbr==0.13.1" # >=0.12.0
  "numpy==2.3.5"              # >=1.26.0
  "numba==0.62.1"             # >=0.59.0
  "llvmlite==0.45.1"          # >=0.44.0,<0.46
  "scipy==1.17.1"             # >=1.12.0
  "attrs==26.1.0"             # >=21.3.0
  "cattrs==26.2.1"            # >=22.1.0
  "msgpack==1.2.4"            # >=1.0.0
  "msgpack-numpy==0.4.8"      # >=0.4.8
  "pyyaml==6.0.3"             # >=5.2
  "click==8.5.1"              # >=8.0.0
  "pillow==13.0.0"            # >=6.2.0
  "h5py==3.16.0"              # >=3.10
  "h11==0.16.0"               # >=0.16.0
  "rich==14.3.4"              # >=14.0.0,<15.0.0
  "numpy-quaternion==2024.0.13" # >=2024.0.12
)

check() {
  # Succeeds only if the venv imports pooltool at the right version and has no torch.
  # HOME points at a throw-away dir because `import pooltool` writes ~/.config/pooltool.
  [ -x "$VENV/bin/python" ] || return 1
  local tmp_home rc
  tmp_home="$(mktemp -d)"
  HOME="$tmp_home" NUMBA_NUM_THREADS=1 "$VENV/bin/python" - "$POOLTOOL_VERSION" <<'EOF' || rc=$?
import importlib.metadata as md, sys
want = sys.argv[1]
assert md.version("pooltool-billiards") == want, md.version("pooltool-billiards")
try:
    md.version("torch")
except md.PackageNotFoundError:
    pass
else:
    raise SystemExit("torch must not be installed in the pooltool venv")
import pooltool as pt
assert pt.__version__ == want, pt.__version__
import numba, llvmlite, numpy, panda3d
print(f"pooltool {pt.__version__} | numba {numba.__version__} | llvmlite "
      f"{llvmlite.__version__} | numpy {numpy.__version__} | panda3d "
      f"{md.version('panda3d')} | python {sys.version.split()[0]} | {sys.executable}")
EOF
  rm -rf "$tmp_home"
  return "${rc:-0}"
}

if check 2>/dev/null; then
  echo "pooltool venv OK at $VENV (nothing to do)"
  exit 0
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "creating venv $VENV with $("$PYTHON" --version 2>&1)"
  "$PYTHON" -m venv "$VENV"
fi

PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)
"${PIP[@]}" install --upgrade pip wheel
"${PIP[@]}" install "${DEPS[@]}"
"${PIP[@]}" install --no-deps "pooltool-billiards==$POOLTOOL_VERSION"

# pip check would complain about the panda3d/llvmlite pins by design; show it for the record.
"${PIP[@]}" check || true

check
# Physics sanity shots; this also fills numba's on-disk cache inside the venv, so the
# ~30-50 s first compile is paid here once and not by the first oracle run.
"$VENV/bin/python" "$HERE/pooltool_oracle.py" --selfcheck
echo "pooltool venv ready at $VENV"
