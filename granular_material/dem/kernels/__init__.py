"""The warp kernels of the DEM engine: contact laws (``laws``), one step (``step``), the
neighbour lists (``lists``), the homogenised measures (``measures``), the block path
(``block``), what they share (``common``) and the kernel sets built per float type (``sets``).
"""
