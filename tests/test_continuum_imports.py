"""Only what the run needs (issue 62): a run of a continuum material (Mohr–Coulomb,
linear-elastic) through the library's one entry point or the command line loads neither
warp, the DEM's batch and kernels, the DEM material, scipy.spatial, scipy.ndimage nor
scipy.special; the DEM's and the procedures' packages load their modules when a name of
theirs is first used."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: modules a continuum run must not load
_NOT_NEEDED = ["warp", "scipy.spatial", "scipy.ndimage", "scipy.special",
               "granular_material.dem.batch",
               "granular_material.dem.model", "granular_material.dem.kernels.sets",
               "granular_material.dem.kernels.step",
               "granular_material.multiscale", "granular_material.procedures.servo",
               "granular_material.procedures.strain_path"]

_RUN = f"""
NOT_NEEDED = {_NOT_NEEDED!r}
import json, sys
from granular_material.runs import run
from granular_material.runs.spec import RunSpec
from granular_material.runs.spec_sections import MaterialSpec, OutputSpec, ProblemSpec
problem = ProblemSpec(test=sys.argv[3], steps=2, axial_strain=0.01,
                      elements=(1, 2) if sys.argv[3] == "biaxial" else None)
spec = RunSpec(problem=problem, material=MaterialSpec(name=sys.argv[2]),
               output=OutputSpec(out=sys.argv[1], progress=False),
               device=None if sys.argv[4] == "none" else sys.argv[4])
outcome = run(spec)
print(json.dumps({{"loaded": [m for m in NOT_NEEDED if m in sys.modules],
                  "steps": len(outcome.result.steps), "device": outcome.summary["device"]
                  if "device" in outcome.summary else None}}))
"""


@pytest.mark.parametrize(("material", "test", "device"), [
    ("mohr-coulomb", "single-element", "none"), ("mohr-coulomb", "biaxial", "cpu"),
    ("linear-elastic", "biaxial", "none")])
def test_a_continuum_run_loads_no_dem(tmp_path, material, test, device):
    done = subprocess.run([sys.executable, "-c", _RUN, str(tmp_path / "run"), material, test,
                           device], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["steps"] == 3
    assert report["loaded"] == []
    if test == "biaxial":
        assert report["device"] == "cpu"


#: modules a continuum run from the command line must not load: the command line shows the
#: DEM material's defaults, so it loads that material's parameters (its package, lazy, and
#: ``multiscale.parameters`` and ``run_hooks``), but not the material, its backend or the DEM
_CLI_NOT_NEEDED = [*(m for m in _NOT_NEEDED if m != "granular_material.multiscale"),
                   "granular_material.multiscale.material", "granular_material.multiscale.backend",
                   "granular_material.dem.homogenization", "granular_material.dem.solver"]

_CLI = f"""
NOT_NEEDED = {_CLI_NOT_NEEDED!r}
import json, sys
from granular_material.cli import main
code = main(["biaxial", "--material", sys.argv[2], "--elements", "1", "2", "--steps", "1",
             "--axial-strain", "0.001", "--no-progress", "--out", sys.argv[1]])
print(json.dumps({{"code": code, "loaded": [m for m in NOT_NEEDED if m in sys.modules]}}))
"""


@pytest.mark.parametrize("material", ["mohr-coulomb", "linear-elastic"])
def test_a_continuum_run_from_the_command_line_loads_no_dem(tmp_path, material):
    done = subprocess.run([sys.executable, "-c", _CLI, str(tmp_path / "run"), material],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report == {"code": 0, "loaded": []}
    assert (tmp_path / "run" / "summary.json").is_file()


def test_the_dem_material_still_loads_by_its_entry_point():
    code = ("import sys\nfrom granular_material.fem import load_material\n"
            "import granular_material.multiscale as m\nbefore = 'warp' in sys.modules\n"
            "cls = load_material('dem')\n"
            "print(before, cls is m.DEMMaterial, cls.Parameters is m.DEMParameters)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=True)
    assert done.stdout.split() == ["False", "True", "True"]


def test_the_packages_load_their_names_on_first_use():
    code = ("import sys\nimport granular_material.dem as dem, granular_material.procedures as p\n"
            "before = 'warp' in sys.modules\n"
            "from granular_material.dem import DEMBatch, RVEMeta\n"
            "from granular_material.procedures import drive_grad_u\n"
            "print(before, 'warp' in sys.modules, DEMBatch.__module__, p.drive_grad_u.__module__,"
            " dem.model.__name__, 'DEMBatch' in dir(dem))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=True)
    assert done.stdout.split() == ["False", "True", "granular_material.dem.batch",
                                   "granular_material.procedures.strain_path",
                                   "granular_material.dem.model", "True"]
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        import granular_material.dem as dem

        dem.no_such_name  # noqa: B018
