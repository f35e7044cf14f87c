"""The condensed (non-affine) tangent of RVEs at equilibrium: the contact network and LU
solves on the host (``tangent``), the batched CG on warp (``cg``, ``cg_kernels``,
``cg_solve``), assembly on the batch's own device (``device``, ``device_kernels``), and
where a batch's tangent is computed (``dispatch``).
"""
