"""Damaged data in a log is reported, never read back as wrong numbers."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from helpers import run_config, small_config

from sitframe.cli.app import main
from sitframe.errors import InputError
from sitframe.logs.reader import open_log


@pytest.fixture(scope="module")
def good_log(tmp_path_factory):
    return run_config(tmp_path_factory.mktemp("integrity"),
                      small_config(name="integrity", trials=1, seed=3), "good.h5")[1]


def _flip_byte_of(path, dataset, tmp_path):
    """Copy the log and flip one byte inside the stored data of ``dataset``."""
    with h5py.File(path, "r") as f:
        ds = f[dataset]
        assert ds.fletcher32, "datasets are written with checksums"
        info = ds.id.get_chunk_info(0)
        offset, size = info.byte_offset, info.size
    data = bytearray(path.read_bytes())
    data[offset + size // 2] ^= 0x40
    bad = tmp_path / "bad.h5"
    bad.write_bytes(bytes(data))
    return bad


def test_every_dataset_has_a_checksum(good_log):
    names = []
    with h5py.File(good_log, "r") as f:
        f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset)
                     and not o.fletcher32 else None)
    assert names == []


def test_flipped_byte_in_an_uncompressed_policy_is_an_input_error(good_log, tmp_path, capsys):
    key = "trials/0000/behaviours/avoid/policy/heading"
    good = open_log(good_log).trial(0).policy("avoid")["heading"]
    bad = _flip_byte_of(good_log, key, tmp_path)
    lg = open_log(bad)  # the structure is intact
    with pytest.raises(InputError, match="corrupted"):
        lg.trial(0)
    with pytest.raises(InputError, match="corrupted"):
        lg.check()
    assert main(["analyse", str(bad), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err
    assert not (tmp_path / "out").exists()
    assert np.array_equal(open_log(good_log).trial(0).policy("avoid")["heading"], good)
