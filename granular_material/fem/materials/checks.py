"""What every material checks of its caller's input before any work: the points it is asked
to allocate (counted, and their memory estimated and refused before it is taken), the ∇u it
is asked to evaluate (real numbers of the right shape; a non-finite value is the point's
failure, never a NaN stress), and the checkpoint it is asked to restore (this material's,
refused by name otherwise)."""

from __future__ import annotations

import numbers
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.errors import ParameterError
from granular_material.memory import available_memory, memory_refusal

__all__ = ["CHECKPOINT_NAME_KEY", "check_grad", "check_points", "checkpoint_archive"]

#: the array of a material's checkpoint that names the material that wrote it
CHECKPOINT_NAME_KEY = "material"


def check_points(n_points: Any, bytes_per_point: float, material: str) -> int:
    """``n_points`` as a count >= 1 whose state (about ``bytes_per_point`` bytes each, the
    evaluation's work arrays included) fits in the memory available now; ParameterError
    naming ``n_points`` with the estimate otherwise. Allocates nothing."""
    if isinstance(n_points, bool) or not isinstance(n_points, numbers.Integral):
        raise ParameterError("n_points", f"must be an integer >= 1, got {n_points!r}")
    n = int(n_points)
    if n < 1:
        raise ParameterError("n_points", f"must be >= 1, got {n}")
    refusal = memory_refusal(float(n) * bytes_per_point,
                             f"{n} Gauss points of the {material} material",
                             available_memory())
    if refusal is not None:
        raise ParameterError("n_points", f"is too many: {refusal}")
    return n


def check_grad(grad_u: Any, n: int) -> np.ndarray:
    """``grad_u`` as float64, batch-first (n, 2, 2); ValueError naming ``grad_u`` for None,
    text, complex values or another shape. Non-finite values pass: they are the failure
    of their points (``FailureReason.NON_FINITE_INPUT``)."""
    if n == 0:
        raise RuntimeError("allocate() the material before evaluate()")
    if grad_u is None:
        raise ValueError(f"grad_u must be an array of shape ({n}, 2, 2), got None")
    array = np.asarray(grad_u)
    if np.iscomplexobj(array):
        raise ValueError("grad_u must be real: ∇u of a displacement has no imaginary part "
                         f"(got complex values, |imag| up to {np.abs(array.imag).max():.3g})")
    if array.dtype.kind not in "biuf":
        raise ValueError(f"grad_u must hold numbers, got an array of {array.dtype}")
    if array.shape != (n, 2, 2):
        raise ValueError(
            f"evaluate() takes grad_u batch-first, shape ({n}, 2, 2) (the increment since the "
            f"commit), got {array.shape}; response() also takes scikit-fem's quadrature-last "
            "(2, 2, nelems, nqp) or a DiscreteField (or convert with "
            "granular_material.fem.to_points / to_quadrature)")
    return np.asarray(array, dtype=np.float64)


@contextmanager
def checkpoint_archive(path: str | Path, material: str,
                       required: tuple[str, ...]) -> Iterator[Any]:
    """The open .npz checkpoint ``path`` of the material ``material``: ValueError naming the
    file and the material that wrote it (another material's checkpoint), or saying that it
    is no checkpoint of ``material`` (not an .npz archive, or without the arrays
    ``required``); FileNotFoundError where it does not exist."""
    path = Path(path)
    if not path.is_file():
        if path.exists():
            raise ValueError(f"{path} is not a file (a checkpoint of the {material} material "
                             "is one .npz file)")
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    try:
        data = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path} is not a checkpoint of the {material} material (not an "
                         f".npz archive: {exc.__class__.__name__})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(f"{path} is not a checkpoint of the {material} material (one array, "
                         "not an .npz archive)")
    with data:
        writer = None
        if CHECKPOINT_NAME_KEY in data.files:
            try:
                writer = str(data[CHECKPOINT_NAME_KEY])
            except ValueError:
                writer = None
        if writer is not None and writer != material:
            raise ValueError(f"{path} is a checkpoint of the {writer} material, not a "
                             f"checkpoint of the {material} material: restore it into a "
                             f"{writer} material")
        missing = [k for k in required if k not in data.files]
        if missing:
            other = ("; it looks like an RVE file (a checkpoint of the dem material)"
                     if "radius" in data.files and "meta" in data.files else "")
            raise ValueError(f"{path} is not a checkpoint of the {material} material (it "
                             f"lacks {', '.join(missing)}){other}")
        yield data
