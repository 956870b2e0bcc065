"""Argument types and parsers every ``fignet-gym`` command group shares: argparse prints their
message and exits 2 on a bad value, before anything runs."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from typing import Any


def int_at_least(low: int) -> Callable[[str], int]:
    """argparse ``type``: an integer ``>= low`` (argparse prints the message and exits 2)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {value}")
        return value
    parse.__name__ = f"integer >= {low}"
    return parse


def _finite_float(text: str, strict: bool) -> float:
    """``text`` as a finite number ``> 0`` (``strict``) or ``>= 0``; ``ArgumentTypeError`` else."""
    bound = "> 0" if strict else ">= 0"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number {bound}, got {text!r}") from None
    if not (math.isfinite(value) and (value > 0 if strict else value >= 0)):
        raise argparse.ArgumentTypeError(f"must be a finite number {bound}, got {text}")
    return value


def positive_float(text: str) -> float:
    """argparse ``type``: a finite number ``> 0``."""
    return _finite_float(text, strict=True)


def nonnegative_float(text: str) -> float:
    """argparse ``type``: a finite number ``>= 0``."""
    return _finite_float(text, strict=False)


def json_overrides(text: str | None) -> dict[str, Any]:
    """``--set``'s JSON object of config overrides (``{}`` when not given); ``ValueError`` else."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise ValueError(f"--set: not JSON ({exc}): {text!r}") from None
    if not isinstance(value, dict):
        raise ValueError(f'--set: expected a JSON object such as \'{{"training.steps": 500}}\', got {text!r}')
    return value
