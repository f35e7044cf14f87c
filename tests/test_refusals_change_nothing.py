"""A refused run changes nothing (docs/cli.md, "What you can rely on"): for every command
that writes a folder (``run`` of a boundary-value, FEM and DEM scene, ``single-element``,
``biaxial``, ``biaxial-dem``, ``dem-drive``) and every kind of refusal (a bad key or option,
a bad or hostile mesh, a resume that differs or meets an older checkpoint, a fresh run over
a stopped one, a folder in use), the folder is byte for byte as it was, its files not even
rewritten (the tree with every file's SHA-256 and modification time compared before and
after), from each state it may be in: absent, empty, a finished run's, a stopped run's
(issue 61, kind 6)."""

from __future__ import annotations

import hashlib
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from run_helpers import PRESSED_BLOCK
from test_bvp_resume import _stop_at
from test_bvp_resume_files import _block

import granular_material.procedures.driven_path as driven_path
import granular_material.procedures.element_tests as element_tests
import granular_material.results.writers as writers
import granular_material.runs.boundary_value.runner as bvp_runner
from granular_material.cli import main
from granular_material.dem import save_rve
from granular_material.fem.materials.linear_elastic import LinearElastic
from granular_material.procedures import prepare_packing
from granular_material.results.lock import FolderLock
from granular_material.runs import from_flat, save

STATES = ("absent", "empty", "finished", "stopped")


def tree(root: Path) -> dict[str, object] | None:
    """Every folder and file under ``root`` (None: there is no ``root``): a file as its
    SHA-256 and modification time [ns], so that a file rewritten unchanged counts too."""
    if not root.exists():
        return None
    listing: dict[str, object] = {}
    for path in sorted(root.rglob("*")):
        name = path.relative_to(root).as_posix()
        listing[name] = ("folder" if path.is_dir() else
                         (hashlib.sha256(path.read_bytes()).hexdigest(),
                          path.stat().st_mtime_ns))
    return listing


def _main(argv: list[str]) -> int:
    """The command line's exit code for ``argv`` (argparse's own refusals included)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def _old_checkpoint(monkeypatch: pytest.MonkeyPatch, folder: Path) -> None:
    """The material refuses its checkpoint, as the DEM material refuses one an older version
    wrote; the checkpoint holds what a resume tidies away (a step file past its state, a
    half-written file), which the refusal must leave."""
    def refuse(self, path):
        raise ValueError(f"{path} was written before this version: start the run afresh")

    monkeypatch.setattr(LinearElastic, "restore", refuse)
    (folder / "checkpoint" / "steps" / "step_00099.npz").write_bytes(b"a later step")
    (folder / "checkpoint" / "state.npz.part").write_bytes(b"half written")


@dataclass
class Command:
    """How to run one command into ``folder`` (in ``tmp``): ``argv(tmp, folder, **change)``,
    what stops it part-way, and the refusals it has (name → ``(states, make)``, where
    ``make(tmp, folder, monkeypatch)`` prepares the refusal and returns its argv)."""

    argv: Callable[..., list[str]]
    stop: Callable[[pytest.MonkeyPatch], None]
    refusals: dict[str, tuple[tuple[str, ...], Callable[..., list[str]]]]
    folder: str = "run"  # what is snapshot, under tmp
    stopped_code: int = 130


# -- a boundary-value scene ----------------------------------------------------------------
BVP_SCENE = """test = "boundary-value"
steps = {steps}
[mesh]
file = "{mesh}"
[boundaries]
base = "y = bottom"
top = "y = top"
""" + PRESSED_BLOCK.format(base="base")


def _bvp(tmp: Path, folder: Path, steps: int = 3, mesh: str = "block.msh",
         extra: str = "", resume: bool = False) -> list[str]:
    if not (tmp / "block.msh").exists():
        _block(tmp / "block.msh")
    scene = tmp / "scene.toml"
    scene.write_text(BVP_SCENE.format(steps=steps, mesh=mesh) + extra)
    return ["run", str(scene), "--out", str(folder), *(["--resume"] if resume else [])]


def _bvp_mesh(text: str | None = None, twice: bool = False) -> Callable[..., list[str]]:
    def make(tmp: Path, folder: Path, _patch: pytest.MonkeyPatch) -> list[str]:
        argv = _bvp(tmp, folder, mesh="other.msh")
        if text is not None:
            (tmp / "other.msh").write_text(text)
        else:  # the block with its first element listed twice
            _block(tmp / "other.msh")
            lines = (tmp / "other.msh").read_text().splitlines()
            at = lines.index("$Elements")
            count = int(lines[at + 1])
            lines[at + 1] = str(count + 1)
            first = lines[at + 2].split()
            lines.insert(at + 2 + count, " ".join([str(count + 1), *first[1:]]))
            (tmp / "other.msh").write_text("\n".join(lines) + "\n")
        return argv
    return make


def _bvp_old(tmp: Path, folder: Path, patch: pytest.MonkeyPatch) -> list[str]:
    _old_checkpoint(patch, folder)
    return _bvp(tmp, folder, resume=True)


def _bvp_moved_mesh(tmp: Path, folder: Path, _patch: pytest.MonkeyPatch) -> list[str]:
    argv = _bvp(tmp, folder, resume=True)
    _block(tmp / "block.msh", 0.05)
    return argv


def _bvp_degenerate(tmp: Path, folder: Path, _patch: pytest.MonkeyPatch) -> list[str]:
    """A generated mesh whose first row of elements has no height."""
    argv = _bvp(tmp, folder)
    scene = tmp / "scene.toml"
    scene.write_text(scene.read_text().replace(
        'file = "block.msh"', "size = [0.4, 0.2]\nelements = [2, 2]\ngrading = [1e-17, 1]"))
    return argv


def _bvp_huge(tmp: Path, folder: Path, _patch: pytest.MonkeyPatch) -> list[str]:
    """A generated mesh of 10¹⁰ elements."""
    argv = _bvp(tmp, folder)
    scene = tmp / "scene.toml"
    scene.write_text(scene.read_text().replace(
        'file = "block.msh"', "size = [0.4, 0.2]\nelements = [100000, 100000]"))
    return argv


def _stray_part(argv: Callable[..., list[str]]) -> Callable[..., list[str]]:
    """The run's command, into a folder that holds a folder ``NAME.part`` (where a file is
    written before it is renamed into place)."""
    def make(tmp: Path, folder: Path, _patch: pytest.MonkeyPatch) -> list[str]:
        (folder / "steps.csv.part").mkdir()
        return argv(tmp, folder)
    return make


BVP = Command(
    argv=_bvp,
    stop=lambda patch: _stop_at(patch, 2),
    refusals={
        "a key that does nothing": (STATES, lambda tmp, folder, _p: _bvp(
            tmp, folder, extra='[[conditions]]\ntype = "roller"\nboundary = "top"\n'
                               'component = "x"\nvalue = 1.0\n')),
        "a mesh file of garbage": (STATES, _bvp_mesh("$MeshFormat\nnot a mesh\n")),
        "an element listed twice": (STATES, _bvp_mesh(twice=True)),
        "degenerate elements": (STATES, _bvp_degenerate),
        "a resume with other steps": (("stopped",), lambda tmp, folder, _p: _bvp(
            tmp, folder, steps=4, resume=True)),
        "a resume after the mesh file changed": (("stopped",), _bvp_moved_mesh),
        "a resume of an older checkpoint": (("stopped",), _bvp_old),
        "a fresh run over a stopped one": (("stopped",), lambda tmp, folder, _p: _bvp(
            tmp, folder)),
        "a mesh beyond memory": (STATES, _bvp_huge),
        "a half-written folder in it": (("empty", "finished", "stopped"),
                                        _stray_part(_bvp)),
    })


# -- the FEM commands and a FEM scene -------------------------------------------------------
def _fem(test: str) -> Callable[..., list[str]]:
    def argv(tmp: Path, folder: Path, steps: int = 3, extra: tuple[str, ...] = (),
             resume: bool = False) -> list[str]:
        words = [test, "--material", "linear-elastic", "--steps", str(steps),
                 "--axial-strain", "0.002", "--device", "cpu", "--no-progress", *extra]
        if test == "biaxial":
            words += ["--elements", "2", "2"]
        return words + (["--resume", str(folder)] if resume else ["--out", str(folder)])
    return argv


def _fem_scene(tmp: Path, folder: Path, steps: int = 3, extra: tuple[str, ...] = (),
               resume: bool = False) -> list[str]:
    scene = tmp / "fem.toml"
    keys = dict(zip(extra[::2], extra[1::2], strict=True))
    scene.write_text('test = "single-element"\nmaterial = "linear-elastic"\n'
                     f"steps = {steps}\naxial_strain = 0.002\n"
                     'device = "cpu"\nprogress = false\n'
                     + "".join(f"{k.removeprefix('--').replace('-', '_')} = {v}\n"
                               for k, v in keys.items()))
    return ["run", str(scene), "--out", str(folder), *(["--resume"] if resume else [])]


def _fem_command(argv: Callable[..., list[str]]) -> Command:
    def old(tmp: Path, folder: Path, patch: pytest.MonkeyPatch) -> list[str]:
        _old_checkpoint(patch, folder)
        return argv(tmp, folder, resume=True)

    def refused_allocation(tmp: Path, folder: Path, patch: pytest.MonkeyPatch) -> list[str]:
        """The material refuses to allocate its points (as the DEM material refuses what it
        cannot prepare)."""
        def refuse(self, n_points):
            raise ValueError(f"cannot allocate {n_points} points")

        patch.setattr(LinearElastic, "allocate", refuse)
        return argv(tmp, folder)

    return Command(
        argv=argv, stop=lambda patch: _stop_at(patch, 2),
        refusals={
            "a bad value": (STATES, lambda tmp, folder, _p: argv(
                tmp, folder, extra=("--young", "-1"))),
            "a resume with other steps": (("stopped",), lambda tmp, folder, _p: argv(
                tmp, folder, steps=4, resume=True)),
            "a resume of an older checkpoint": (("stopped",), old),
            "a fresh run over a stopped one": (("stopped",), lambda tmp, folder, _p: argv(
                tmp, folder)),
            "a half-written folder in it": (("empty", "finished", "stopped"),
                                            _stray_part(argv)),
            "a material that refuses its allocation": (STATES[:3], refused_allocation),
        })


# -- the DEM commands and a DEM scene -------------------------------------------------------
@pytest.fixture(scope="module")
def rve16(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rve") / "rve16.npz"
    save_rve(path, prepare_packing(n_disc=16, seed=1, pressure=100e3, device="cpu").to_data())
    return path


RVE: dict[str, Path] = {}


def _dem(test: str) -> Callable[..., list[str]]:
    def argv(tmp: Path, folder: Path, rve: Path | None = None, extra: tuple[str, ...] = (),
             resume: bool = False, fresh: bool = False) -> list[str]:
        words = [test, str(rve or RVE["rve"]), "--device", "cpu", "--no-progress",
                 "--out", str(folder / ("curve.csv" if test == "biaxial-dem" else "path.csv"))]
        if test == "biaxial-dem":
            words += ["--axial-strain", "0.002", "--record-every", "20", "--plot",
                      str(folder / "curve.png")]
        else:
            words += ["--grad-u=0,0,0,-0.001", "--increments", "3"]
        return [*words, *extra, *(["--resume"] if resume else []),
                *(["--fresh"] if fresh else [])]
    return argv


def _dem_scene(tmp: Path, folder: Path, rve: Path | None = None, extra: tuple[str, ...] = (),
               resume: bool = False, fresh: bool = False) -> list[str]:
    scene = tmp / "dem.toml"
    keys = dict(zip(extra[::2], extra[1::2], strict=True))
    scene.write_text(f'test = "biaxial-dem"\nrve = "{rve or RVE["rve"]}"\n'
                     'axial_strain = 0.002\nrecord_every = 20\ndevice = "cpu"\n'
                     "progress = false\n"
                     + "".join(f"{k.removeprefix('--').replace('-', '_')} = {v}\n"
                               for k, v in keys.items()))
    return ["run", str(scene), "--out", str(folder), *(["--resume"] if resume else [])]


def _dem_command(argv: Callable[..., list[str]], stop: Callable[[pytest.MonkeyPatch], None],
                 scene: bool = False) -> Command:
    def garbage(tmp: Path, folder: Path, _patch: pytest.MonkeyPatch) -> list[str]:
        bad = tmp / "bad.npz"
        bad.write_bytes(b"PK\x03\x04 not an RVE file")
        return argv(tmp, folder, rve=bad, **({} if scene else {"fresh": True}))

    refusals = {
        "a bad value": (STATES, lambda tmp, folder, _p: argv(
            tmp, folder, extra=("--confining", "-1"))),
        "an RVE file that cannot be read": (("absent", "empty", "finished"), garbage),
        "a resume with other options": (("stopped",), lambda tmp, folder, _p: argv(
            tmp, folder, extra=("--confining", "200000"), resume=True)),
        "a fresh run over a stopped one": (("stopped",), lambda tmp, folder, _p: argv(
            tmp, folder)),
    }
    if not scene:  # --fresh over a stopped run, from an RVE file that cannot be read
        refusals["a fresh start from an RVE file that cannot be read"] = (("stopped",),
                                                                          garbage)
    return Command(argv=argv, refusals=refusals, stop=stop)


def _interrupt_on_call(patch: pytest.MonkeyPatch, module, name: str, call: int) -> None:
    """``module.name`` raises KeyboardInterrupt on its ``call``-th call."""
    real = getattr(module, name)
    calls = {"n": 0}

    def wrapped(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == call:
            raise KeyboardInterrupt("signal")
        return real(*args, **kwargs)

    patch.setattr(module, name, wrapped)


def _stop_biaxial_dem(patch: pytest.MonkeyPatch) -> None:
    _interrupt_on_call(patch, element_tests, "servo_steps", 2)


def _stop_drive(patch: pytest.MonkeyPatch) -> None:
    _interrupt_on_call(patch, driven_path, "drive_grad_u", 2)


def _spec_file(tmp: Path, folder: Path, steps: int = 3, extra: tuple[str, ...] = (),
               resume: bool = False) -> list[str]:
    """``run SPEC.toml`` of a single element's run specification."""
    path = tmp / "spec.toml"
    values = {"test": "single-element", "material": "linear-elastic", "steps": steps,
              "axial_strain": 0.002, "device": "cpu", "progress": False}
    save(from_flat(values), path)
    for key, value in zip(extra[::2], extra[1::2], strict=True):  # a value it refuses
        name = key.removeprefix("--")
        path.write_text(re.sub(rf"(?m)^{name} = .*$", f"{name} = {value}", path.read_text()))
    return ["run", str(path), "--out", str(folder), *(["--resume"] if resume else [])]


def _prepare_argv(tmp: Path, folder: Path, extra: tuple[str, ...] = ()) -> list[str]:
    return ["prepare", "--particles", "16", "--seed", "2", "--device", "cpu",
            "--no-progress", "--out", str(folder / "rve.npz"), *extra]


#: prepare keeps no checkpoint: a stopped one is run again (no "stopped" state)
PREPARE = Command(
    argv=_prepare_argv, stop=lambda patch: None,
    refusals={
        "a bad value": (STATES[:3], lambda tmp, folder, _p: _prepare_argv(
            tmp, folder, ("--pressure", "-1"))),
        "a batch beyond memory": (STATES[:3], lambda tmp, folder, _p: _prepare_argv(
            tmp, folder, ("--batch", "100000000"))),
    })
COMMANDS = {
    "run boundary-value": BVP,
    "single-element": _fem_command(_fem("single-element")),
    "biaxial": _fem_command(_fem("biaxial")),
    "run single-element": _fem_command(_fem_scene),
    "run SPEC.toml": _fem_command(_spec_file),
    "prepare": PREPARE,
    "biaxial-dem": _dem_command(_dem("biaxial-dem"), _stop_biaxial_dem),
    "dem-drive": _dem_command(_dem("dem-drive"), _stop_drive),
    "run biaxial-dem": _dem_command(_dem_scene, _stop_biaxial_dem, scene=True),
}
CASES = [pytest.param(command, refusal, state, id=f"{command}|{refusal}|{state}")
         for command, spec in COMMANDS.items()
         for refusal, (states, _) in spec.refusals.items() for state in states]
# a folder in use is refused by its lock whatever it holds: from the state with most to lose
CASES += [pytest.param(command, "a folder in use", state, id=f"{command}|in use|{state}")
          for command in COMMANDS for state in (("finished",) if command == "prepare"
                                                else ("stopped",))]


def _figure_stub(*args, **kwargs) -> Path:
    """A figure's file written as a few bytes (its path: the first Path among the
    arguments)."""
    path = next(a for a in (*args, *kwargs.values()) if isinstance(a, Path))
    path.write_bytes(b"figure")
    return path


def _prepare(command: Command, state: str, tmp: Path, folder: Path,
             monkeypatch: pytest.MonkeyPatch) -> None:
    """``folder`` in ``state``: absent, empty, or holding a finished or stopped run."""
    if state == "absent":
        return
    folder.mkdir(parents=True)
    if state == "empty":
        return
    with monkeypatch.context() as patch:
        # the figures drawn as small files (what they hold is no matter here: drawing them
        # is most of a small run's time)
        for module, name in ((writers, "plot_maps"), (writers, "plot_stress_strain"),
                             (bvp_runner, "plot_load_displacement"),
                             (bvp_runner, "plot_mechanism")):
            patch.setattr(module, name, _figure_stub)
        if state == "stopped":
            command.stop(patch)
        code = main(command.argv(tmp, folder))
    assert code == (command.stopped_code if state == "stopped" else 0), state


@pytest.mark.parametrize(("command", "refusal", "state"), CASES)
def test_a_refused_run_leaves_its_folder_as_it_was(command, refusal, state, tmp_path,
                                                    monkeypatch, capsys, rve16):
    RVE["rve"] = rve16
    spec = COMMANDS[command]
    folder = tmp_path / spec.folder
    _prepare(spec, state, tmp_path, folder, monkeypatch)
    # the snapshot of the folder, but for the scene text the refusal writes beside it
    lock = None
    if refusal == "a folder in use":
        argv = spec.argv(tmp_path, folder, **({"resume": True} if state == "stopped" else {}))
        held = folder if command in ("run boundary-value", "single-element", "biaxial",
                                     "run single-element", "run SPEC.toml",
                                     "run biaxial-dem") else None
        if held is None:  # a DEM command locks the checkpoint folder beside its output
            out = Path(argv[argv.index("--out") + 1])
            held = out.with_name(out.name + ".checkpoint")
        lock = FolderLock(held)
        lock.acquire()
    else:
        argv = spec.refusals[refusal][1](tmp_path, folder, monkeypatch)
    before = tree(folder)
    capsys.readouterr()
    try:
        code = _main(argv)
        after = tree(folder)  # the holder's lock file still there
    finally:
        if lock is not None:
            lock.release()
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert after == before, err


def test_the_cases_cover_every_command_and_state() -> None:
    """The family above: every command, each from every state it can be refused in."""
    assert {c.values[0] for c in CASES} == set(COMMANDS)
    assert {c.values[2] for c in CASES} == set(STATES)
    assert len(CASES) >= 100


def test_a_scene_refused_before_its_run_leaves_no_scene_copy_to_trip_a_resume(tmp_path,
                                                                             capsys):
    """A scene refused at build (an element listed twice) leaves no scene.toml; the
    corrected scene then runs, and a later --resume of it is not refused as another
    scene's."""
    folder = tmp_path / "run"
    assert main(_bvp_mesh(twice=True)(tmp_path, folder, None)) == 2
    assert not folder.exists()
    assert main(_bvp(tmp_path, folder, resume=True)) == 0
    assert (folder / "scene.toml").read_text() == (tmp_path / "scene.toml").read_text()
    shutil.rmtree(folder)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_output_that_is_the_wrong_kind_of_thing_is_refused_unchanged(command, tmp_path,
                                                                        capsys, rve16):
    """The run folder given as an existing file (a DEM command's output file given as an
    existing folder): refused, the file (folder) and all beside it as they were."""
    RVE["rve"] = rve16
    spec = COMMANDS[command]
    folder = tmp_path / spec.folder
    argv = spec.argv(tmp_path, folder)
    out = Path(argv[argv.index("--out") + 1])
    if out == folder:  # a folder's command: the folder is a file
        folder.write_bytes(b"not a folder")
    else:  # a file's command: its output file is a folder
        out.mkdir(parents=True)
        (out / "kept.txt").write_text("kept")
    before = tree(tmp_path)
    capsys.readouterr()
    code = _main(argv)
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    assert tree(tmp_path) == before, err
