#!/usr/bin/env bash
# Test suite (default run excludes tests marked slow; pass `-m slow` to run those).
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
cd "$ROOT"
set +e
"$PY" -m pytest -q "$@"
code=$?
set -e
if [ "$code" -eq 5 ]; then
  echo "ERROR: pytest collected no tests (exit 5); treating as failure." >&2
  exit 1
fi
exit "$code"
