"""The layered ground under a strip footing: half the domain (the footing's axis on the
left), a 1 m upper layer over a 3 m lower one, meshed by gmsh in second-order triangles
(tri6).

    python examples/scenes/meshes/footing-layered.py    # writes footing-layered.msh

Needs the gmsh Python package (``pip install gmsh``; not a dependency of granular-material,
only of remaking this mesh). The geometry [m]: x from 0 (the axis) to 5, y from -4 to 0, the
layers meeting at y = -1, the footing's half-width 1 m.

Physical groups, read by the boundary-value scenes as regions and boundary names: cells
``upper`` (y > -1) and ``lower``; lines ``footing`` (y = 0, x <= 1), ``surface`` (y = 0,
x >= 1), ``left`` (the axis), ``right`` and ``base``. Elements of 0.1 m at the footing's
edge, growing to 0.6 m away from it.
"""

from __future__ import annotations

from pathlib import Path

import gmsh

#: element sizes [m]: at the footing's edge, under the footing and at the layers' meeting,
#: and far away
EDGE, NEAR, FAR = 0.1, 0.25, 0.6


def build(path: Path) -> int:
    """Mesh the layered ground into ``path`` (gmsh format 2.2); returns the number of
    tri6."""
    gmsh.initialize(interruptible=False)  # leave the process's signal handlers alone
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("footing-layered")
        geo = gmsh.model.geo
        sizes = {(0, 0): NEAR, (1, 0): EDGE, (5, 0): FAR, (0, -1): NEAR, (5, -1): FAR,
                 (0, -4): FAR, (5, -4): FAR}
        p = {xy: geo.addPoint(xy[0], xy[1], 0.0, size) for xy, size in sizes.items()}
        lines = {
            "footing": [geo.addLine(p[0, 0], p[1, 0])],
            "surface": [geo.addLine(p[1, 0], p[5, 0])],
            "right": [geo.addLine(p[5, 0], p[5, -1]), geo.addLine(p[5, -1], p[5, -4])],
            "base": [geo.addLine(p[5, -4], p[0, -4])],
            "left": [geo.addLine(p[0, -4], p[0, -1]), geo.addLine(p[0, -1], p[0, 0])],
        }
        interface = geo.addLine(p[5, -1], p[0, -1])
        (footing,), (surface,), (base,) = lines["footing"], lines["surface"], lines["base"]
        right_upper, right_lower = lines["right"]
        left_lower, left_upper = lines["left"]
        upper = geo.addPlaneSurface([geo.addCurveLoop([footing, surface, right_upper,
                                                       interface, left_upper])])
        lower = geo.addPlaneSurface([geo.addCurveLoop([-interface, right_lower, base,
                                                       left_lower])])
        geo.synchronize()
        for name, tags in lines.items():
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, tags), name)
        for name, tag in (("upper", upper), ("lower", lower)):
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [tag]), name)
        gmsh.model.mesh.generate(2)
        gmsh.model.mesh.setOrder(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(path))
        _, tags, _ = gmsh.model.mesh.getElements(2)
        return int(sum(len(t) for t in tags))
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    out = Path(__file__).with_suffix(".msh")
    print(f"{out}: {build(out)} tri6")
