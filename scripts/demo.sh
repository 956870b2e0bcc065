#!/usr/bin/env bash
# Main job: a demo on the shipped pretrained simulators (no training needed).
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
exec "$PY" -m fignet_gym demo "$@"
