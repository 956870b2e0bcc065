"""The one error path of every ``fignet-gym`` command: a user's mistake is one ``error:`` line and
exit status 2; a bug keeps its traceback."""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Callable

from fignet_gym.data.generate import GenerationError
from fignet_gym.dynamics.mujoco import collect_warnings


def user_error(err: BaseException) -> str | None:
    """The one-line message for an error caused by the user's input, ``None`` for a bug.

    Known user errors: bad or missing files (checkpoints, trajectory files, run folders,
    unreadable paths), refused overwrites, unsupported scenes, and ``ValueError`` from argument
    and config checks. Their messages already name the file and field.
    """
    # Every error class the library raises for bad input (CheckpointError, TrajectoryFormatError,
    # RunFolderError, UnsupportedSceneError, PlanError, the PPO RunError, ...) is a ValueError.
    if isinstance(err, OSError) and not isinstance(err, (FileExistsError, FileNotFoundError)):
        name = err.filename if err.filename is not None else ""
        return f"{name}: {err.strerror or err}" if name else str(err)
    if isinstance(err, (ValueError, FileExistsError, FileNotFoundError, GenerationError)):
        return str(err)
    return None


def run_command(func: Callable[[argparse.Namespace], int | None], args: argparse.Namespace) -> int:
    """Run a subcommand: a user error prints ``error: <file>: <what>`` and returns 2 (set
    ``FIGNET_GYM_TRACEBACK=1`` for the traceback); anything else (a bug) propagates. MuJoCo's
    warnings are counted into one line at the end (stages that expect them, such as the contact
    fit, summarise their own), never printed one by one nor written to ``MUJOCO_LOG.TXT``."""
    default_show = warnings.showwarning

    def one_line(message: Warning | str, category: type[Warning], *rest: object, **kw: object) -> None:
        if issubclass(category, DeprecationWarning):  # for developers: as Python shows them
            default_show(message, category, *rest, **kw)  # type: ignore[arg-type]
            return
        print(f"warning: {message}", file=sys.stderr)  # a user reads the fix, not our source line

    with collect_warnings() as warned, warnings.catch_warnings():
        warnings.showwarning = one_line
        try:
            return int(func(args) or 0)
        except KeyboardInterrupt:
            print("error: interrupted", file=sys.stderr)
            return 130
        except Exception as err:  # noqa: BLE001 - classified below, re-raised if not a user error
            msg = user_error(err)
            if msg is None or os.environ.get("FIGNET_GYM_TRACEBACK"):
                raise
            print(f"error: {msg}", file=sys.stderr)
            return 2
        finally:
            if warned:
                times = "once" if len(warned) == 1 else f"{len(warned)} times"
                print(f"MuJoCo warned {times} (first: {warned[0]}); a simulation that "
                      "went unstable holds its last finite poses and is scored as it is",
                      file=sys.stderr)
