"""The embankment of the slope scenes: 10 m high at 1.5:1 (horizontal:vertical) on a 5 m
foundation layer, meshed by gmsh in second-order triangles (tri6).

    python examples/scenes/meshes/embankment.py      # writes embankment.msh beside it

Needs the gmsh Python package (``pip install gmsh``; not a dependency of granular-material,
only of remaking this mesh). The geometry [m]: the crest from x = 0 to 15 at y = 10, the face
down to the toe at (30, 0), level ground to x = 50, the foundation from y = 0 down to y = -5
over the whole width. The left side (x = 0) is where a symmetric embankment's axis would be.

Physical groups, read by the boundary-value scenes as regions and boundary names:
cells ``embankment`` (above y = 0) and ``foundation``; lines ``base`` (y = -5), ``left``
(x = 0, both layers), ``right`` (x = 50), ``crest``, ``face`` and ``toe`` (the level ground
beyond the toe). Elements of about 1.5 m, 0.75 m along the face and near the toe.
"""

from __future__ import annotations

from pathlib import Path

import gmsh

#: element sizes [m]: far from the slope, and along the face and at the toe
COARSE, FINE = 1.5, 0.75


def build(path: Path) -> int:
    """Mesh the embankment into ``path`` (gmsh format 2.2); returns the number of tri6."""
    gmsh.initialize(interruptible=False)  # leave the process's signal handlers alone
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("embankment")
        geo = gmsh.model.geo
        sizes = {(0, -5): COARSE, (50, -5): COARSE, (50, 0): COARSE, (30, 0): FINE,
                 (0, 0): COARSE, (0, 10): COARSE, (15, 10): FINE}
        p = {xy: geo.addPoint(xy[0], xy[1], 0.0, size) for xy, size in sizes.items()}
        lines = {
            "base": [geo.addLine(p[0, -5], p[50, -5])],
            "right": [geo.addLine(p[50, -5], p[50, 0])],
            "toe": [geo.addLine(p[50, 0], p[30, 0])],
            "face": [geo.addLine(p[30, 0], p[15, 10])],
            "crest": [geo.addLine(p[15, 10], p[0, 10])],
            "left": [geo.addLine(p[0, 10], p[0, 0]), geo.addLine(p[0, 0], p[0, -5])],
        }
        interface = geo.addLine(p[30, 0], p[0, 0])
        base, right, toe = lines["base"][0], lines["right"][0], lines["toe"][0]
        face, crest = lines["face"][0], lines["crest"][0]
        left_upper, left_lower = lines["left"]
        embankment = geo.addPlaneSurface([geo.addCurveLoop([interface, -left_upper, -crest,
                                                            -face])])
        foundation = geo.addPlaneSurface([geo.addCurveLoop([base, right, toe, interface,
                                                            left_lower])])
        geo.synchronize()
        for name, tags in lines.items():
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, tags), name)
        for name, tag in (("embankment", embankment), ("foundation", foundation)):
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
