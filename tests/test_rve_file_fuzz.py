"""Property test: a mutated RVE file is refused naming a field, or runs to a finite stress.

Each example takes a valid 64-disc file (contact history included) and applies one to three
mutations: a value (NaN, ±inf, out-of-range indices, huge, tiny, arbitrary floats), a dtype,
a shape, a dropped array or meta key, emptied lists, a wrong-typed meta value. Loading it and
driving it 0.01 % in shear must end in one of: ``RVEFileError``/``ValueError`` (exit 2)
naming a field of the file, ``DEMInstabilityError`` (exit 1, a blow-up named by RVE), or a
finite stress. Any other exception fails the test, and a signal kills it.

The default run tries ``GM_FUZZ_EXAMPLES`` files (300); the ``slow`` test tries 1000.
"""

from __future__ import annotations

import json
import os
import warnings
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from granular_material.dem import DEMBatch, DEMInstabilityError, load_rve, save_rve
from granular_material.dem.rve.file import CONTACT_HISTORY_KEYS
from granular_material.procedures import drive_grad_u

N_DISC = 64
CORE = ("radius", "position", "cell", "velocity", "angular_velocity")
ARRAYS = (*CORE, *CONTACT_HISTORY_KEYS)
META_KEYS = ("thickness", "density", "friction_angle", "damping", "stiffness", "seed",
             "timestep", "format_version")
STIFFNESS_KEYS = ("law", "kn", "kt", "young", "kt_over_kn")
#: the names a refusal may give: the file's arrays, the meta, or the time step it implies
FIELD_NAMES = (*ARRAYS, "meta", "timestep")
GRAD_U = np.array([[0.0, 1e-4], [0.0, 0.0]])  # 10 steps at 1e-5 strain a step

Arrays = dict[str, np.ndarray]


class Mutation:
    """A change of a file's arrays, in place; called, it returns the field a refusal must
    name, or None where any field may be named (a finite value can break a check on another
    field). A mutation of an array the file no longer has does nothing."""

    def __init__(self, what: str, key: str | None,
                 change: Callable[[Arrays], str | None]) -> None:
        self.what, self.key, self.change = what, key, change

    def __call__(self, arrays: Arrays) -> str | None:
        if self.key is not None and self.key not in arrays:
            return None
        return self.change(arrays)

    def __repr__(self) -> str:
        return self.what


class Valid(tuple):
    """(arrays of a valid file, folder to write mutated ones to), with a short repr."""

    def __repr__(self) -> str:
        return "<valid 64-disc RVE file>"


@pytest.fixture(scope="module")
def valid(tmp_path_factory: pytest.TempPathFactory) -> Valid:
    """The arrays of a valid 64-disc file, and a folder to write mutated ones to."""
    from granular_material.procedures import prepare_packing

    batch = prepare_packing(n_disc=N_DISC, n_rve=1, seed=7, pressure=100e3, device="cpu")
    folder = tmp_path_factory.mktemp("fuzz")
    save_rve(folder / "valid.npz", batch.to_data())
    with np.load(folder / "valid.npz") as npz:
        return Valid(({k: np.array(npz[k]) for k in npz.files}, folder))


SPECIAL_FLOATS = (np.nan, np.inf, -np.inf, 0.0, -0.0, 1e300, -1e300, 5e-324, -1.0, 1.0, 0.5)
SPECIAL_INTS = (-1, -5, N_DISC, N_DISC - 1, 10**6, -(2**31), 2**31 - 1, 16, 17, 0)


@st.composite
def set_value(draw: st.DrawFn) -> Mutation:
    key = draw(st.sampled_from(ARRAYS))
    position = draw(st.integers(min_value=0, max_value=10**6))
    as_int = draw(st.one_of(st.sampled_from(SPECIAL_INTS), st.integers(-(2**31), 2**31 - 1)))
    as_float = draw(st.one_of(st.sampled_from(SPECIAL_FLOATS), st.floats()))

    def mutate(arrays: Arrays) -> str | None:
        flat = arrays[key].reshape(-1)
        if flat.size == 0:
            return None
        if flat.dtype.kind in "iu":
            if np.iinfo(flat.dtype).min <= as_int <= np.iinfo(flat.dtype).max:
                flat[position % flat.size] = as_int
            return None
        with np.errstate(over="ignore", invalid="ignore"):  # e.g. 1e300 into float32: inf
            flat[position % flat.size] = as_float
        return key if not np.isfinite(as_float) else None

    return Mutation(f"{key}.flat[{position}] = {as_int} / {as_float}", key, mutate)


@st.composite
def set_dtype(draw: st.DrawFn) -> Mutation:
    key = draw(st.sampled_from(ARRAYS))
    dtype = draw(st.sampled_from([np.str_, np.bool_, np.complex128, np.float32, np.float64,
                                  np.int64, np.int8, np.uint16]))

    def mutate(arrays: Arrays) -> str | None:
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")  # complex to real drops the imaginary part
                arrays[key] = arrays[key].astype(dtype)
        except (ValueError, OverflowError):  # e.g. "True" (a bool made text) as a float
            return None
        accepted = "iu" if key in ("contact_partner", "contact_count") else "iuf"
        return key if np.dtype(dtype).kind not in accepted else None

    return Mutation(f"{key} as {np.dtype(dtype)}", key, mutate)


SHAPES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "cut last column": lambda a: a[..., : max(a.shape[-1] - 1, 0)] if a.ndim else a,
    "cut to 4 columns": lambda a: a[..., :4] if a.ndim else a,
    "add a column": lambda a: np.concatenate([a, a[..., :1]], axis=-1) if a.ndim else a,
    "drop a disc": lambda a: a[:, :-1] if a.ndim > 1 else a,
    "flatten": lambda a: a.reshape(-1),
    "drop the batch axis": lambda a: a[0] if a.ndim and len(a) else a,  # an emptied one stays
    "add a batch": lambda a: np.concatenate([a, a]) if a.ndim else a,
    "scalar": lambda a: np.asarray(a.reshape(-1)[0]) if a.size else np.asarray(0.0),
    "empty": lambda a: a[:0],
    "transpose": lambda a: a.T,
}


@st.composite
def set_shape(draw: st.DrawFn) -> Mutation:
    key = draw(st.sampled_from(ARRAYS))
    how = draw(st.sampled_from(sorted(SHAPES)))

    def mutate(arrays: Arrays) -> str | None:
        before = arrays[key].shape
        arrays[key] = np.ascontiguousarray(SHAPES[how](arrays[key]))
        return key if arrays[key].shape != before else None

    return Mutation(f"{key}: {how}", key, mutate)


@st.composite
def drop_array(draw: st.DrawFn) -> Mutation:
    key = draw(st.sampled_from((*ARRAYS, "meta")))

    def mutate(arrays: Arrays) -> str | None:
        del arrays[key]
        return key

    return Mutation(f"drop {key}", key, mutate)


@st.composite
def drop_history(draw: st.DrawFn) -> Mutation:
    """Every history array removed: the engine builds fresh lists (must run)."""
    draw(st.just(None))

    def mutate(arrays: Arrays) -> str | None:
        for key in CONTACT_HISTORY_KEYS:
            arrays.pop(key, None)
        return None

    return Mutation("drop the history", None, mutate)


@st.composite
def empty_lists(draw: st.DrawFn) -> Mutation:
    keep = draw(st.integers(min_value=0, max_value=N_DISC - 1))  # discs that keep theirs

    def mutate(arrays: Arrays) -> str | None:
        if "contact_count" in arrays and arrays["contact_count"].ndim == 2:
            arrays["contact_count"][:, keep:] = 0
        return None

    return Mutation(f"empty the lists of discs {keep}:", "contact_count", mutate)


@st.composite
def scale(draw: st.DrawFn) -> Mutation:
    key = draw(st.sampled_from(("velocity", "angular_velocity", "contact_shear_force",
                                "verlet_displacement", "radius", "cell")))
    factor = draw(st.sampled_from((0.0, 0.5, 0.99, 1.01, 2.0, -1.0, 1e3, 1e-3)))

    def mutate(arrays: Arrays) -> str | None:
        if key in arrays and arrays[key].dtype.kind == "f":
            with np.errstate(over="ignore"):
                arrays[key] = arrays[key] * factor
        return None

    return Mutation(f"{key} *= {factor}", key, mutate)


JSON_VALUES = st.one_of(
    st.text(max_size=5), st.none(), st.booleans(), st.integers(-(10**20), 10**20),
    st.floats(), st.sampled_from(["0.5", "constant", "frictmat", "1e-6", [], {}, [0.1]]),
    st.dictionaries(st.sampled_from(STIFFNESS_KEYS),
                    st.one_of(st.sampled_from(["constant", "frictmat"]), st.floats(),
                              st.booleans(), st.none(), st.text(max_size=3)), max_size=5),
)


@st.composite
def set_meta(draw: st.DrawFn) -> Mutation:
    key = draw(st.sampled_from((*META_KEYS, *(f"stiffness.{k}" for k in STIFFNESS_KEYS))))
    drop = draw(st.booleans())
    value = draw(JSON_VALUES)

    def mutate(arrays: Arrays) -> str | None:
        if "meta" not in arrays or arrays["meta"].dtype.kind != "U" or arrays["meta"].ndim:
            return None
        meta = json.loads(str(arrays["meta"]))
        where, name = meta, key
        if key.startswith("stiffness."):
            if not isinstance(meta.get("stiffness"), dict):
                return None
            where, name = meta["stiffness"], key.split(".", 1)[1]
        if drop:
            where.pop(name, None)
        else:
            where[name] = value
        arrays["meta"] = np.array(json.dumps(meta))
        return None  # e.g. a changed stiffness refuses the stored time step: "timestep"

    return Mutation(f"meta.{key}: " + ("drop" if drop else repr(value)), "meta", mutate)


MUTATIONS = st.lists(
    st.one_of(set_value(), set_dtype(), set_shape(), drop_array(), drop_history(),
              empty_lists(), scale(), set_meta()),
    min_size=1, max_size=3,
)

OUTCOMES: Counter[str] = Counter()


def _try(arrays: Arrays, path: Path) -> str:
    """Load and drive the file of ``arrays``; the outcome's class, or an assertion."""
    np.savez(path, **arrays)
    try:
        data = load_rve(path)
        batch = DEMBatch(data, device="cpu", shards=1)
        drive_grad_u(batch, GRAD_U)
        stress = batch.homogenize().stress
    except DEMInstabilityError as exc:
        assert "RVE" in str(exc)
        return "blow-up (exit 1)"
    except ValueError as exc:  # RVEFileError included: exit 2
        return f"refused: {exc}"
    assert np.isfinite(stress).all(), stress
    return "ran"


def _check(valid: Valid, mutations: list[Mutation]) -> None:
    base, folder = valid
    arrays = {k: v.copy() for k, v in base.items()}
    named = [mutate(arrays) for mutate in mutations]
    outcome = _try(arrays, folder / "mutated.npz")
    if outcome.startswith("refused"):
        message = outcome.split(": ", 1)[1]
        assert any(name in message for name in FIELD_NAMES), message
        if all(named):  # each mutation's field is known: one of them is named
            assert any(name in message for name in named), (named, message)
        OUTCOMES["refused (exit 2)"] += 1
    else:
        OUTCOMES[outcome] += 1


EXAMPLES = int(os.environ.get("GM_FUZZ_EXAMPLES", "300"))
_SETTINGS = {"deadline": None, "database": None, "derandomize": False,
             "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture]}


@settings(max_examples=EXAMPLES, **_SETTINGS)
@given(mutations=MUTATIONS)
def test_mutated_files_are_refused_or_run_bounded(valid, mutations):
    _check(valid, mutations)


@pytest.mark.slow
def test_a_thousand_mutated_files(valid):
    """Run with ``-m slow``: at least 1000 mutated files, and both outcomes seen."""
    OUTCOMES.clear()

    @settings(max_examples=1000, **_SETTINGS)
    @given(mutations=MUTATIONS)
    def run(mutations: list[Mutation]) -> None:
        _check(valid, mutations)

    run()
    print(f"\nmutated files tried: {sum(OUTCOMES.values())}: {dict(OUTCOMES)}")
    assert sum(OUTCOMES.values()) >= 1000
    assert OUTCOMES["ran"] > 0 and OUTCOMES["refused (exit 2)"] > 0


def test_the_valid_file_runs_and_an_emptied_one_is_refused(valid):
    """The two outcomes the property test relies on both occur (it could fail)."""
    base, folder = valid
    assert _try({k: v.copy() for k, v in base.items()}, folder / "plain.npz") == "ran"
    emptied = {k: v.copy() for k, v in base.items()}
    emptied["contact_count"][:] = 0
    assert "misses the overlapping pair" in _try(emptied, folder / "emptied.npz")
