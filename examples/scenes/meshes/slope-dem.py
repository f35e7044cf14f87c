"""The reduced DEM slope of slope-dem-reduced.toml: 1 m high at 2:1 (horizontal:vertical) on a
0.5 m base, meshed by gmsh in linear triangles (tri3, one Gauss point each: one RVE per
element).

    python examples/scenes/meshes/slope-dem.py      # writes slope-dem.msh beside it

Needs the gmsh Python package (``pip install gmsh``; not a dependency of granular-material,
only of remaking this mesh). The geometry [m]: the crest from x = 0 to 1.5 at y = 1, the face
down to the toe at (3.5, 0), level ground to x = 5, the base layer from y = 0 down to y = -0.5
over the whole width.

Physical groups, read by the scene as boundary names: cells ``soil``; lines ``base``
(y = -0.5), ``left`` (x = 0), ``right`` (x = 5), ``crest``, ``face`` and ``toe`` (the level
ground beyond the toe). Elements of about 0.3 m: 155 tri3.
"""

from __future__ import annotations

from pathlib import Path

import gmsh

#: element size [m]
SIZE = 0.3


def build(path: Path, size: float = SIZE) -> int:
    """Mesh the slope into ``path`` (gmsh format 2.2) with elements of about ``size`` [m];
    returns the number of tri3."""
    gmsh.initialize(interruptible=False)  # leave the process's signal handlers alone
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("slope-dem")
        geo = gmsh.model.geo
        corners = ((0, -0.5), (5, -0.5), (5, 0), (3.5, 0), (1.5, 1), (0, 1), (0, 0))
        p = {xy: geo.addPoint(xy[0], xy[1], 0.0, size) for xy in corners}
        lines = {
            "base": [geo.addLine(p[0, -0.5], p[5, -0.5])],
            "right": [geo.addLine(p[5, -0.5], p[5, 0])],
            "toe": [geo.addLine(p[5, 0], p[3.5, 0])],
            "face": [geo.addLine(p[3.5, 0], p[1.5, 1])],
            "crest": [geo.addLine(p[1.5, 1], p[0, 1])],
            "left": [geo.addLine(p[0, 1], p[0, 0]), geo.addLine(p[0, 0], p[0, -0.5])],
        }
        loop = geo.addCurveLoop([tag for tags in lines.values() for tag in tags])
        soil = geo.addPlaneSurface([loop])
        geo.synchronize()
        for name, tags in lines.items():
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, tags), name)
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [soil]), "soil")
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(path))
        _, tags, _ = gmsh.model.mesh.getElements(2)
        return int(sum(len(t) for t in tags))
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    target = Path(__file__).with_name("slope-dem.msh")
    print(f"{build(target)} tri3 written to {target}")
