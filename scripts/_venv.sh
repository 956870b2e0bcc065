# Sourced by demo.sh and test.sh: create or reuse .venv and install what the project needs.
# torch is pinned to 2.13.0 here (a CPU wheel that lies on the reference machines' disk); the
# project's own range stays open for users elsewhere.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${FIGNET_GYM_VENV:-$ROOT/.venv}"
PY="$VENV/bin/python"
if [ ! -x "$PY" ]; then
  python3 -m venv "$VENV"
fi
STAMP="$VENV/.fignet_gym_installed"
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ]; then
  LOG="$VENV/install.log"
  echo "installing into $VENV (log: $LOG) ..."
  {
    "$PY" -m pip install --upgrade pip &&
    "$PY" -m pip install "torch==2.13.0" &&
    "$PY" -m pip install -e "$ROOT[dev]"
  } > "$LOG" 2>&1 || { tail -n 40 "$LOG"; echo "installation failed (see $LOG)" >&2; exit 1; }
  touch "$STAMP"
fi
export MUJOCO_GL="${MUJOCO_GL:-egl}"
# With every core busy, OpenMP threads that spin while waiting for each other make torch many times
# slower; passive waiting costs nothing when cores are free.
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-PASSIVE}"
