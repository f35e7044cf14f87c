"""Every field of an RVE file is checked on load: a bad one is named (exit 2), never a crash."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from granular_material.cli import main
from granular_material.dem import DEMBatch, RVEFileError, load_rve, save_rve
from granular_material.dem.model import build_model
from granular_material.dem.rve.file import CONTACT_HISTORY_KEYS
from granular_material.dem.state import HISTORY_KEYS
from granular_material.procedures import drive_grad_u

N_DISC = 64


@pytest.fixture(scope="module")
def rve64(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 64-disc RVE consolidated to 100 kPa, written with its contact history."""
    from granular_material.procedures import prepare_packing

    batch = prepare_packing(n_disc=N_DISC, n_rve=1, seed=5, pressure=100e3, device="cpu")
    path = tmp_path_factory.mktemp("rve64") / "rve64.npz"
    save_rve(path, batch.to_data())
    return path


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as npz:
        return {k: np.array(npz[k]) for k in npz.files}


def _write(path: Path, arrays: dict[str, np.ndarray], **meta_changes: object) -> Path:
    """Write ``arrays`` as they are (no validation), with meta keys changed (None drops)."""
    arrays = dict(arrays)
    if meta_changes:
        meta = json.loads(str(arrays["meta"]))
        for key, value in meta_changes.items():
            if value is _DROP:
                meta.pop(key, None)
            else:
                meta[key] = value
        arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)
    return path


_DROP = object()


def _first_pair(arrays: dict[str, np.ndarray]) -> tuple[int, int, int]:
    """(i, k, j): disc i's slot k holds partner j (the first used slot)."""
    count = arrays["contact_count"][0]
    i = int(np.argmax(count > 0))
    return i, 0, int(arrays["contact_partner"][0, i, 0])


def test_history_keys_are_the_engines(rve64):
    assert CONTACT_HISTORY_KEYS == HISTORY_KEYS
    data = load_rve(rve64)
    assert set(HISTORY_KEYS) <= set(data.extra)
    assert data.extra["contact_count"].max() > 0


def test_a_valid_file_round_trips(rve64, tmp_path):
    data = load_rve(rve64)
    save_rve(tmp_path / "again.npz", data)
    again = load_rve(tmp_path / "again.npz")
    for key in HISTORY_KEYS:
        np.testing.assert_array_equal(again.extra[key], data.extra[key])


@pytest.mark.parametrize("value", [10**6, N_DISC, -5, 1000])
def test_partner_out_of_range_is_named(rve64, tmp_path, value):
    arrays = _arrays(rve64)
    i, k, _ = _first_pair(arrays)
    arrays["contact_partner"][0, i, k] = value
    with pytest.raises(RVEFileError, match=rf"contact_partner must lie in \[0, {N_DISC}\).*"
                                           rf"{value}"):
        load_rve(_write(tmp_path / "bad.npz", arrays))


@pytest.mark.parametrize("value", [-3, 10**6, 17])
def test_count_out_of_range_is_named(rve64, tmp_path, value):
    arrays = _arrays(rve64)
    arrays["contact_count"][0, 3] = value
    with pytest.raises(RVEFileError, match=rf"contact_count must lie in \[0, 16\].*{value}"):
        load_rve(_write(tmp_path / "bad.npz", arrays))


def test_cut_partner_array_is_refused(rve64, tmp_path):
    """Four columns cannot hold the lists (up to 8 partners): refused, never truncated."""
    arrays = _arrays(rve64)
    assert arrays["contact_count"].max() > 4
    arrays["contact_partner"] = arrays["contact_partner"][..., :4]
    with pytest.raises(RVEFileError, match=r"contact_shear_force.*contact_partner"):
        load_rve(_write(tmp_path / "cut.npz", arrays))
    arrays["contact_shear_force"] = arrays["contact_shear_force"][..., :4]
    with pytest.raises(RVEFileError, match=r"contact_count must lie in \[0, 4\]"):
        load_rve(_write(tmp_path / "cut.npz", arrays))


def test_emptied_lists_are_refused(rve64, tmp_path):
    """Empty lists while discs overlap would leave every contact without force (σ = 0)
    until the engine's skin test next rebuilds them: the file is refused."""
    arrays = _arrays(rve64)
    arrays["contact_count"][:] = 0
    arrays["contact_partner"][:] = -1
    with pytest.raises(RVEFileError, match=r"contact_partner.*misses the overlapping pair"):
        load_rve(_write(tmp_path / "empty.npz", arrays))


def test_history_removed_rebuilds_the_lists(rve64, tmp_path):
    """The remedy the message names: without any history arrays the lists are rebuilt."""
    arrays = {k: v for k, v in _arrays(rve64).items() if k not in HISTORY_KEYS}
    data = load_rve(_write(tmp_path / "fresh.npz", arrays))
    stress = DEMBatch(data, device="cpu", shards=1).homogenize().stress[0]
    assert -stress[0, 0] > 50e3 and -stress[1, 1] > 50e3


def test_partial_history_is_refused(rve64, tmp_path):
    arrays = _arrays(rve64)
    del arrays["contact_count"]
    with pytest.raises(RVEFileError, match=r"history is incomplete.*lacks contact_count"):
        load_rve(_write(tmp_path / "partial.npz", arrays))


def test_asymmetric_duplicate_and_self_partners_are_refused(rve64, tmp_path):
    arrays = _arrays(rve64)
    i, k, j = _first_pair(arrays)
    # j no longer lists i: i's slot of j's list now names a disc not related to either
    mirror = int(np.argmax(arrays["contact_partner"][0, j] == i))
    other = next(m for m in range(N_DISC)
                 if m not in (i, j) and m not in arrays["contact_partner"][0, j])
    bad = {**arrays, "contact_partner": arrays["contact_partner"].copy()}
    bad["contact_partner"][0, j, mirror] = other
    with pytest.raises(RVEFileError, match="not symmetric"):
        load_rve(_write(tmp_path / "asym.npz", bad))
    bad["contact_partner"] = arrays["contact_partner"].copy()
    two = int(np.argmax(arrays["contact_count"][0] >= 2))
    bad["contact_partner"][0, two, 1] = bad["contact_partner"][0, two, 0]
    with pytest.raises(RVEFileError, match="more than once"):
        load_rve(_write(tmp_path / "dup.npz", bad))
    bad["contact_partner"] = arrays["contact_partner"].copy()
    bad["contact_partner"][0, i, k] = i
    with pytest.raises(RVEFileError, match="own partner"):
        load_rve(_write(tmp_path / "self.npz", bad))


def test_the_two_copies_of_a_pairs_force_must_agree(rve64, tmp_path):
    arrays = _arrays(rve64)
    i, k, _ = _first_pair(arrays)
    arrays["contact_shear_force"][0, i, k] += 1.0
    with pytest.raises(RVEFileError, match=r"contact_shear_force.*differs"):
        load_rve(_write(tmp_path / "force.npz", arrays))


@pytest.mark.parametrize("key", ["fractional_position", "contact_shear_force",
                                 "verlet_displacement", "cell_at_list_build"])
@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_history_is_named(rve64, tmp_path, key, value):
    arrays = _arrays(rve64)
    arrays[key].reshape(-1)[1] = value
    with pytest.raises(RVEFileError, match=f"{key} holds a non-finite value"):
        load_rve(_write(tmp_path / "nan.npz", arrays))


def test_fractional_position_must_match_and_lie_in_the_unit_cell(rve64, tmp_path):
    arrays = _arrays(rve64)
    arrays["fractional_position"][0, 7, 0] += 1e-3
    with pytest.raises(RVEFileError, match="fractional_position does not match"):
        load_rve(_write(tmp_path / "drift.npz", arrays))
    arrays = _arrays(rve64)
    arrays["fractional_position"][0, 7, 1] = 1.5
    with pytest.raises(RVEFileError, match=r"fractional_position must lie in \[0, 1\]"):
        load_rve(_write(tmp_path / "out.npz", arrays))


def test_fractional_position_one_as_the_engine_rounds_it_loads(rve64, tmp_path):
    """``s − floor(s)`` is exactly 1 for s = −1e-17: such a file (the engine's) loads."""
    arrays = _arrays(rve64)
    frac = arrays["fractional_position"][0]
    frac[:, 0] = (frac[:, 0] - frac[7, 0]) % 1.0  # a rigid shift: disc 7 at s0 = 0
    frac[7, 0] = 1.0  # the same place
    arrays["position"][0] = frac @ arrays["cell"][0].T
    data = load_rve(_write(tmp_path / "one.npz", arrays))
    drive_grad_u(DEMBatch(data, device="cpu", shards=1), np.array([[0.0, 1e-4], [0.0, 0.0]]))


@pytest.mark.parametrize(("key", "dtype"), [("contact_partner", np.float64),
                                            ("contact_count", np.float32),
                                            ("contact_shear_force", np.str_),
                                            ("radius", np.str_), ("cell", np.bool_)])
def test_wrong_dtypes_are_named(rve64, tmp_path, key, dtype):
    arrays = _arrays(rve64)
    arrays[key] = arrays[key].astype(dtype)
    with pytest.raises(RVEFileError, match=f"{key} must hold"):
        load_rve(_write(tmp_path / "dtype.npz", arrays))


def test_lists_must_fit_the_engines_capacity(rve64):
    data = load_rve(rve64)
    assert data.extra["contact_count"].max() > 4
    with pytest.raises(RVEFileError, match="capacity of 4 slots"):
        build_model(data, device="cpu", capacity=4)


def test_cell_narrower_than_the_cut_off_is_bad_input(two_discs):
    # a cell of 24 mm: solid area fine, but 2 * cut-off (2 * 12.5 mm) is not below it
    data = two_discs((0.005, 0.005), (0.017, 0.017), cell=np.eye(2) * 0.024)
    with pytest.raises(RVEFileError, match="too narrow for its discs"):
        DEMBatch(data, device="cpu")


def test_unknown_unbatched_array_is_ignored_with_a_warning(rve64, tmp_path):
    arrays = _arrays(rve64)
    arrays["notes"] = np.array("made by hand")
    with pytest.warns(UserWarning, match="ignoring array.*notes"):
        data = load_rve(_write(tmp_path / "notes.npz", arrays))
    assert "notes" not in data.extra
    DEMBatch(data, device="cpu", shards=1)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("friction_angle", "0.5", "meta.friction_angle must be a number"),
        ("density", "2650", "meta.density must be a number"),
        ("density", None, "meta.density must be a number"),
        ("damping", "x", "meta.damping must be a number"),
        ("timestep", "1e-6", "meta.timestep must be a number"),
        ("stiffness", "constant", "meta.stiffness must be an object"),
        ("stiffness", {"law": "constant", "kn": True, "kt": 2.4e6}, "meta.stiffness.kn"),
        ("stiffness", {"law": "constant", "kt": 2.4e6}, "meta.stiffness.kn"),
        ("stiffness", {"law": "frictmat", "young": "6e8", "kt_over_kn": 0.8},
         "meta.stiffness.young"),
        ("thickness", [0.1], "meta.thickness must be a number"),
        ("friction_angle", 2.0, "meta.friction_angle must lie in"),
        ("seed", 1.5, "meta.seed"),
        ("format_version", "1", "meta.format_version"),
        ("friction_angle", _DROP, "meta lacks friction_angle"),
        ("stiffness", _DROP, "meta lacks stiffness"),
        ("density", _DROP, "meta lacks density"),
    ],
)
def test_meta_types_and_missing_keys_are_named(rve64, tmp_path, key, value, message):
    path = _write(tmp_path / "meta.npz", _arrays(rve64), **{key: value})
    with pytest.raises(RVEFileError, match=message):
        load_rve(path)
    assert main(["dem-drive", str(path), "--grad-u", "0,0.001,0,0", "--increments", "1",
                 "--out", str(tmp_path / "out" / "x.csv")]) == 2
    assert not (tmp_path / "out").exists()


def test_meta_json_nan_is_named(rve64, tmp_path):
    arrays = _arrays(rve64)
    arrays["meta"] = np.array(str(arrays["meta"]).replace('"damping": 0.1', '"damping": NaN'))
    with pytest.raises(RVEFileError, match=r"meta.damping must be finite"):
        load_rve(_write(tmp_path / "nan.npz", arrays))


def _cli() -> list[str]:
    script = Path(sys.executable).with_name("granular-material")
    if script.exists():
        return [str(script)]
    found = shutil.which("granular-material")
    if found:
        return [found]
    return [sys.executable, "-c", "import sys; from granular_material.cli import main; "
            "sys.exit(main())"]


def test_cli_bad_partner_index_exits_2_naming_the_field(rve64, tmp_path):
    """Was a segmentation fault (exit 139): now exit 2 and the field named on stderr."""
    arrays = _arrays(rve64)
    i, k, _ = _first_pair(arrays)
    arrays["contact_partner"][0, i, k] = 10**6
    bad = _write(tmp_path / "bad.npz", arrays)
    out = tmp_path / "out" / "path.csv"
    proc = subprocess.run(
        [*_cli(), "dem-drive", str(bad), "--grad-u", "0,0.001,0,0", "--increments", "1",
         "--device", "cpu", "--out", str(out)],
        capture_output=True, text=True, timeout=300, check=False,
    )
    assert proc.returncode == 2, proc.stderr
    assert "contact_partner" in proc.stderr and "1000000" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()


@pytest.mark.parametrize(("key", "value"), [("velocity", 1e6), ("angular_velocity", 1e9)])
def test_a_state_already_blown_up_is_bad_input(rve64, tmp_path, key, value):
    """A speed that moves a disc more than r/4 in one step (the engine's blow-up limit)."""
    arrays = _arrays(rve64)
    arrays[key][0, 3] = value
    path = _write(tmp_path / "fast.npz", arrays)
    data = load_rve(path)  # a finite number: the file itself is readable
    with pytest.raises(RVEFileError, match=f"{key} of disc 3 of RVE 0 is beyond"):
        DEMBatch(data, device="cpu", shards=1)
    assert main(["dem-drive", str(path), "--grad-u", "0,0.001,0,0", "--increments", "1",
                 "--out", str(tmp_path / "o" / "x.csv")]) == 2


def test_coincident_discs_are_named(two_discs):
    data = two_discs((0.05, 0.1), (0.05, 0.1))
    with pytest.raises(RVEFileError, match="position of discs 0 and 1 of RVE 0 coincide"):
        DEMBatch(data, device="cpu")
