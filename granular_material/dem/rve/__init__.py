"""The RVE batch as data and as a file (docs/design.md#rve-file): its data model (``data``),
the file format's constants and meta (``format``), its checks (``checks``) and the ``.npz``
file (``file``).
"""
