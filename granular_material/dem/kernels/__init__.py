"""The warp kernels of the DEM engine: contact laws (``laws``), one step (``step``), the
neighbour lists (``lists``), the homogenised measures (``measures``), the block path
(``block``), what they share (``common``) and the kernel sets built per float type (``sets``).
"""

__all__ = ["DTYPES"]

#: the float types the kernels are built for (here, so that a run specification can check a
#: dtype without building or importing a kernel)
DTYPES = ("float64", "float32")
