"""What the kernels share: the status bits of an RVE, the servo's control codes, and the
array annotations of generic kernel arguments."""

from __future__ import annotations

from typing import Any

import warp as wp

__all__ = [
    "CONTROL_STRAIN",
    "CONTROL_STRESS",
    "STATUS_BLOWUP",
    "STATUS_CELL_TOO_SMALL",
    "STATUS_COINCIDENT",
    "STATUS_OVERFLOW",
    "AnyArray",
    "IntArray",
]

STATUS_BLOWUP = 1  #: a velocity became non-finite or a disc moved > r/4 in one step
STATUS_OVERFLOW = 2  #: a neighbour list exceeded its capacity
STATUS_CELL_TOO_SMALL = 4  #: contact cut-off above half a perpendicular cell height
STATUS_COINCIDENT = 8  #: two disc centres coincide

CONTROL_STRAIN = 0  #: a diagonal component driven at a prescribed strain per step
CONTROL_STRESS = 1  #: a diagonal component servo-controlled to a target stress

IntArray = wp.array(dtype=wp.int32)  #: an int32 array argument
AnyArray = wp.array(dtype=Any)  #: an array of the kernel's float type (scalar, vector, matrix)
