"""What every command shares: the options (device, dtype, progress, json, out) defined once,
their argument types, the one way results are reported on stdout."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "UsageError",
    "add_device",
    "add_dtype",
    "add_json",
    "add_out",
    "add_progress",
    "emit",
    "ensure_parents",
    "positive",
    "positive_int",
    "progress_enabled",
    "scalar_or_list",
]


class UsageError(ValueError):
    """Bad input from the user: reported on stderr with exit code 2."""


def positive(text: str) -> float:
    """argparse type: a positive finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def add_device(parser: argparse.ArgumentParser, what: str = "warp device") -> None:
    """``--device cpu|cuda`` (default None: CUDA when present, else CPU)."""
    parser.add_argument("--device", choices=["cpu", "cuda"], default=None,
                        help=f"{what} (default: CUDA when present, else CPU)")


def add_dtype(parser: argparse.ArgumentParser) -> None:
    """``--dtype float64|float32`` of the DEM."""
    parser.add_argument("--dtype", choices=["float64", "float32"], default="float64",
                        help="floating-point precision of the DEM (default: float64)")


def add_progress(parser: argparse.ArgumentParser) -> None:
    """``--progress/--no-progress`` (default: when stderr is a terminal)."""
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="progress bars on stderr (default: when stderr is a terminal)")


def add_json(parser: argparse.ArgumentParser, what: str = "the key results") -> None:
    """``--json``: the report as JSON on stdout."""
    parser.add_argument("--json", action="store_true", help=f"print {what} as JSON on stdout")


def add_out(parser: argparse.ArgumentParser, help: str, default: Path | None = None) -> None:
    """``--out PATH`` (a file or a folder, as ``help`` says)."""
    parser.add_argument("--out", type=Path, default=default, help=help)


def progress_enabled(args: argparse.Namespace) -> bool:
    """Whether to show progress bars: ``--progress/--no-progress``, else stderr is a tty."""
    return sys.stderr.isatty() if args.progress is None else bool(args.progress)


def scalar_or_list(values: np.ndarray) -> Any:
    """A batch of B values as a JSON value: the value itself when B = 1, else a list."""
    values = np.asarray(values)
    listed = values.tolist()
    return listed[0] if values.shape[0] == 1 else listed


def emit(args: argparse.Namespace, result: dict[str, Any]) -> None:
    """Report ``result`` on stdout: JSON with ``--json``, else one aligned line per key."""
    if args.json:
        json.dump(result, sys.stdout, indent=2, default=str)
        sys.stdout.write("\n")
    else:
        for key, value in result.items():
            print(f"{key:>24}: {value}")


def ensure_parents(*paths: Path | None) -> None:
    """Create the folders of the output files up front, so a bad path fails before the run."""
    for path in paths:
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
