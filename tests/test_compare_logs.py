"""`compare_logs`, on which every bit-identical check of the suite rests (workers, Dask,
resume, sweeps, seeds), reports each kind of difference: a changed byte in any dataset,
a changed dtype or shape, a changed attribute, a missing dataset or group."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest

from sitframe.logs.compare import compare_logs


def _write(path) -> None:
    """A small log-shaped file: nested groups, datasets of every dtype kind a log holds,
    attributes on groups and datasets, an empty group, a root attribute."""
    with h5py.File(path, "w") as f:
        f.attrs["created"] = "2026-01-01T00:00:00"
        t = f.create_group("trials/0000")
        t.attrs["index"] = 0
        t.attrs["seed"] = np.uint64(2**63 + 5)
        t.attrs["world"] = "training"
        t["pose"] = np.linspace(0.0, 1.0, 12).reshape(4, 3)
        t["pose"].attrs["units"] = "m, m, rad"
        t["collision"] = np.array([False, True, False])
        t["rule_base"] = np.arange(6, dtype=np.int16)
        t["note"] = "converged"  # a scalar string
        t["labels"] = np.array(["avoid", "goal"], dtype=h5py.string_dtype())
        t["summary"] = np.array([(1, 2.5)], dtype=[("trial", "i8"), ("coverage", "f8")])
        t["q"] = np.array([[np.nan, -0.0], [1e-300, 3.0]])
        f.create_group("trials/0000/eval")  # empty


DATASETS = ["trials/0000/pose", "trials/0000/collision", "trials/0000/rule_base",
            "trials/0000/note", "trials/0000/labels", "trials/0000/summary", "trials/0000/q"]


@pytest.fixture
def pair(tmp_path):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    _write(a)
    shutil.copyfile(a, b)
    return a, b


def test_a_copy_is_identical_and_root_attributes_are_ignored(pair):
    a, b = pair
    assert compare_logs(a, b) == []
    with h5py.File(b, "a") as f:  # when and how the run ended is not a result
        f.attrs["created"] = "2030-01-01T00:00:00"
        f.attrs["status"] = "complete"
    assert compare_logs(a, b) == []


@pytest.mark.parametrize("name", DATASETS)
def test_one_changed_byte_in_any_dataset_is_found(pair, name):
    a, b = pair
    with h5py.File(b, "a") as f:
        old = f[name][()]
        if isinstance(old, bytes):
            new = old[:-1] + bytes([old[-1] ^ 1])
        elif old.dtype.kind == "O":
            new = old.copy()
            new[-1] = new[-1][:-1] + b"X"
        else:
            raw = bytearray(old.tobytes())
            raw[-1] ^= 1  # the lowest bit of the last element
            new = np.frombuffer(bytes(raw), dtype=old.dtype).reshape(old.shape)
        f[name][()] = new
    assert compare_logs(a, b) == [name]
    assert compare_logs(b, a) == [name]


def test_bit_identical_means_bits_not_values(pair):
    a, b = pair
    with h5py.File(b, "a") as f:  # -0.0 == 0.0 as a number, not as a result
        q = f["trials/0000/q"][()]
        q[0, 1] = 0.0
        f["trials/0000/q"][()] = q
    assert compare_logs(a, b) == ["trials/0000/q"]


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (lambda f: f["trials/0000"].attrs.modify("world", "novel-1"), "trials/0000@world"),
        (lambda f: f["trials/0000"].attrs.modify("seed", np.uint64(2**63 + 6)),
         "trials/0000@seed"),
        (lambda f: f["trials/0000/pose"].attrs.modify("units", "m"), "trials/0000/pose@units"),
        (lambda f: f["trials/0000"].attrs.__setitem__("index", np.int32(0)),
         "trials/0000@index"),
    ],
    ids=["group-attr", "uint64-attr", "dataset-attr", "attr-dtype"],
)
def test_a_changed_attribute_is_found(pair, change, expected):
    a, b = pair
    with h5py.File(b, "a") as f:
        change(f)
    assert compare_logs(a, b) == [expected]


def test_dtype_and_shape_changes_with_the_same_bytes_are_found(pair):
    a, b = pair
    with h5py.File(b, "a") as f:
        pose = f["trials/0000/pose"][()]
        del f["trials/0000/pose"]
        f["trials/0000/pose"] = pose.reshape(3, 4)
        f["trials/0000/pose"].attrs["units"] = "m, m, rad"
        rules = f["trials/0000/rule_base"][()]
        del f["trials/0000/rule_base"]
        f["trials/0000/rule_base"] = rules.view(np.uint16)
    assert compare_logs(a, b) == ["trials/0000/pose", "trials/0000/rule_base"]


def test_missing_dataset_attribute_and_group_are_found(pair):
    a, b = pair
    with h5py.File(b, "a") as f:
        del f["trials/0000/collision"]
        del f["trials/0000/eval"]
        del f["trials/0000"].attrs["world"]
    expected = ["trials/0000/collision", "trials/0000/eval/", "trials/0000@world"]
    assert compare_logs(a, b) == expected
    assert compare_logs(b, a) == expected
    with h5py.File(b, "a") as f:
        del f["trials/0000"]
    assert "trials/0000/" in compare_logs(a, b)
    assert set(compare_logs(a, b)) >= set(DATASETS)


def test_files_without_trials_compare_too(tmp_path):
    """(e.g. a log cut down to its stages): groups, datasets and attributes as usual."""
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    for p, v in ((a, 1.0), (b, 2.0)):
        with h5py.File(p, "w") as f:
            f["cluster/centers"] = np.full((2, 2), v)
    assert compare_logs(a, a) == [] and compare_logs(a, b) == ["cluster/centers"]
