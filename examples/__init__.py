"""The examples, installed with the package as ``granular_material_examples``.

- :mod:`granular_material_examples.skfem_material_swap`: a scikit-fem script (MeshQuad Q1 or
  MeshTri P2, its own Newton loop, total ∇u in scikit-fem's layout) whose material is
  ``linear-elastic`` or ``dem`` by one line; run it with
  ``python -m granular_material_examples.skfem_material_swap [linear-elastic|dem] [quad1|tri2]``.
- ``scenes/*.toml``: scene files for ``granular-material run``.

Find the files with ``importlib.resources.files("granular_material_examples")``.
"""
