"""A log reads back exactly what the run wrote, and a log that cannot be read says why.

One small log written by :class:`LogWriter` (no simulation: hand-made trials), read back
through every reader of :mod:`sitframe.logs`: the run's attributes, the stages, the fitted
situations, each trial's arrays, behaviour data, policies, episodes, plugin data,
situations and summary, and the summary table. Then the refusals a user meets: a file that
is not a log, a damaged attribute, a missing stage or trial, a second writer, a full disk.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import stat

import h5py
import numpy as np
import pytest

import sitframe.logs.writer as L
from sitframe.contract.records import LearnedPolicy, PolicyOutput, RunInfo, TrialResult
from sitframe.errors import InputError
from sitframe.logs.reader import open_log
from sitframe.logs.writer import LogWriter, code_fingerprint

CONFIG = '[experiment]\nname = "rt"\n\n[sensor]\ncomponent = "pioneer-sonar"\n'
SENSOR = {"name": "ring", "angles_deg": [-30.0, 0.0, 30.0], "max_range": 2.5, "unit": "m"}
PLUGINS = [{"name": "fuzzy-q", "origin": "built-in", "distribution": "sitframe",
            "version": "1.0", "file": ""}]


def _info(path, **extra) -> RunInfo:
    return RunInfo("rt", {}, CONFIG, "c0ffee", 7, str(path), 2, 4, PLUGINS,
                   {"training": 'name = "training"'},
                   {"source": "presets/rt.toml", "versions": {"sitframe": "1.0"},
                    "sensor": SENSOR, "inputs": {"policy_from/avoid": "ab12"},
                    "code_hash": "feed", **extra})


def _trial(k: int) -> TrialResult:
    rng = np.random.default_rng(k)
    arrays = {"pose": rng.random((5, 3)), "reading": rng.random((4, 3)),
              "memberships": rng.random((4, 2)), "collision": np.array([0, 1, 0, k], bool),
              "weights": np.ones((4, 2)), "proposals/avoid": rng.random((4, 2))}
    policy = LearnedPolicy({
        "heading": PolicyOutput(np.array([-30.0, 0.0, 30.0]), np.array([2, 0]), "deg",
                                rng.random((2, 3))),
        "speed": PolicyOutput(np.array([0.1, 0.3]), np.array([1, k % 2]), "m/s"),
        "turn": PolicyOutput(np.array([-1.0, 1.0]), np.array([0, 1]), "rad")})
    return TrialResult(
        k, 2**63 + k, "training", arrays, {"avoid": {"heading/q_snapshots": rng.random((2, 2, 3)),
                                                    "note": "kept", "steps": 3,
                                                    "deep/er/x": np.arange(2), "ks": [1, 2]},
                                          "goal": {"distance": np.array([1.5])}},
        {"converged": bool(k), "convergence_iteration": 3 - k, "eval/novel-1/coverage": 0.25},
        episodes={"success": np.array([True, False])}, policies={"avoid": policy},
        plugin_data={"observer": {"hits": np.arange(3)}},
        situations={"count": 2, "state/centers": np.ones((2, 3)), "events/kind": np.array([1])})


@pytest.fixture
def written(tmp_path):
    """A complete log of trials 1 and 0 (written in that order), with both stages (made
    for each test, ~0.1 s: every test that reads it checks what the writer wrote)."""
    path = tmp_path / "logs" / "rt.h5"
    w = LogWriter(path)
    w.start(_info(path))
    w.stage("collect", {"samples": np.arange(6.0).reshape(2, 3), "worlds": ["a", "b"]})
    w.stage("cluster", {"state/centers": np.eye(2, 3), "state/m": 2.0, "chosen": 2})
    w.trial(_trial(1), ["avoid", "goal"])
    w.trial(_trial(0), ["avoid", "goal"])
    w.set_status("complete")
    w.release()
    return path


def test_the_runs_attributes_read_back(written):
    log = open_log(written)
    assert (log.status, log.complete, log.failure) == ("complete", True, None)
    assert log.config == {"experiment": {"name": "rt"}, "sensor": {"component": "pioneer-sonar"}}
    assert log.worlds == {"training": 'name = "training"'}
    assert log.plugins == PLUGINS and log.versions == {"sitframe": "1.0"}
    s = log.sensor
    assert (s.name, s.angles_deg.tolist(), s.max_range, s.unit) == \
        ("ring", [-30.0, 0.0, 30.0], 2.5, "m")
    a = log.attrs
    assert (a["name"], a["config_hash"], a["seed"], a["n_trials"], a["iterations"]) == \
        ("rt", "c0ffee", 7, 2, 4)
    assert (a["source"], a["code_hash"], json.loads(a["inputs"])) == \
        ("presets/rt.toml", "feed", {"policy_from/avoid": "ab12"})
    assert a["schema"] == "sitframe-log" and a["schema_version"] == 1


def test_stages_and_fitted_situations_read_back(written):
    log = open_log(written)
    assert log.has("collect") and log.has("cluster/state") and not log.has("evaluate")
    collect = log.stage("collect")
    assert collect["samples"].tolist() == [[0, 1, 2], [3, 4, 5]]
    assert json.loads(collect["worlds"]) == ["a", "b"]
    assert log.stage("cluster")["chosen"] == 2
    state = log.interpreter_state()
    assert np.array_equal(state["centers"], np.eye(2, 3)) and state["m"] == 2.0
    with h5py.File(written, "r") as f:  # what the reader relies on: checksums, units
        assert f["collect/samples"].fletcher32
        assert f["trials/0000/pose"].attrs["units"].startswith("x [m]")


def test_a_trial_reads_back_bit_for_bit(written):
    log = open_log(written)
    assert log.trial_indices() == [0, 1]
    want = _trial(1)
    t = log.trial(1)
    assert (t.index, t.seed, t.world) == (1, 2**63 + 1, "training")
    assert t.summary == {"converged": True, "convergence_iteration": 2,
                         "eval/novel-1/coverage": 0.25}
    assert sorted(t.arrays) == ["collision", "memberships", "pose", "proposals/avoid",
                                "reading", "sonar", "weights"]
    for k, v in want.arrays.items():
        assert t.arrays[k].dtype == v.dtype and t.arrays[k].tobytes() == v.tobytes(), k
    assert np.array_equal(t.arrays["sonar"], want.arrays["reading"])  # the name before v2
    b = t.behaviours["avoid"]
    assert np.array_equal(b["heading/q_snapshots"], want.behaviours["avoid"]["heading/q_snapshots"])
    assert (b["note"], b["steps"]) == ("kept", 3)
    assert b["deep/er/x"].tolist() == [0, 1] and b["ks"].tolist() == [1, 2]
    assert t.episodes["success"].tolist() == [True, False]
    assert t.plugins["observer"]["hits"].tolist() == [0, 1, 2]
    assert t.situations_part("state")["centers"].tolist() == [[1.0] * 3] * 2
    assert list(t.situations_part("events")) == ["kind"]
    assert t.situations_part("events")["kind"].tolist() == [1]
    assert t.situations["count"] == 2
    with h5py.File(written, "r") as f:
        assert json.loads(f["trials/0001/weights"].attrs["columns"]) == ["avoid", "goal"]
        assert f["trials/0001/behaviours/avoid/policy/heading"].dtype == np.int16


def test_learned_policies_read_back(written):
    t = open_log(written).trial(0)
    want = _trial(0).policies["avoid"].outputs
    assert set(t.policies) == {"avoid"}
    got = t.learned_policy("avoid").outputs
    assert list(got) == ["heading", "speed", "turn"]
    for out in ("heading", "speed", "turn"):
        assert got[out].actions.tolist() == want[out].actions.tolist()
        assert got[out].rules.tolist() == want[out].rules.tolist()
        assert got[out].unit == want[out].unit
    assert np.array_equal(got["heading"].q, want["heading"].q) and got["speed"].q is None
    assert t.policy("avoid")["heading"].tolist() == [2, 0]
    assert t.learned_policy("goal") is None  # a behaviour that learns nothing
    with pytest.raises(ValueError, match=r"has no behaviour 'avoyd'; it has: .*avoid"):
        t.learned_policy("avoyd")  # a typo is not "learned nothing"


def test_a_policy_logged_before_contract_v2_reads_with_its_old_names(written, tmp_path):
    old = tmp_path / "old.h5"
    old.write_bytes(written.read_bytes())
    with h5py.File(old, "a") as f:
        g = f["trials/0000/behaviours/avoid"]
        g.move("actions", "singletons")
        del g["units"]
        g.move("q/heading", "heading/q")
    got = open_log(old).trial(0).learned_policy("avoid").outputs
    assert (got["heading"].unit, got["speed"].unit, got["turn"].unit) == ("deg", "m/s", "")
    assert got["heading"].actions.tolist() == [-30.0, 0.0, 30.0]
    assert np.array_equal(got["heading"].q, _trial(0).policies["avoid"].outputs["heading"].q)


def test_a_damaged_policy_names_the_trial_and_output(written, tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(written.read_bytes())
    with h5py.File(bad, "a") as f:
        del f["trials/0001/behaviours/avoid/policy/speed"]
        f["trials/0001/behaviours/avoid/policy/speed"] = np.array([0, 5], np.int16)
    with pytest.raises(InputError, match="logged policy of trial 1 is damaged") as e:
        open_log(bad).trial(1).learned_policy("avoid")
    assert e.value.key == "trials/0001/behaviours/avoid/policy/speed"
    with pytest.raises(InputError, match=r"action indices in 0\.\.1, got \[0, 5\]"):
        open_log(bad).check()


def test_the_summary_table_has_a_row_per_trial_in_trial_order(written):
    table = open_log(written).summary()
    assert table.dtype.names == ("trial", "converged", "convergence_iteration",
                                 "eval.novel-1.coverage")
    assert table["trial"].tolist() == [0, 1]
    assert table["converged"].tolist() == [0.0, 1.0]
    assert table["convergence_iteration"].tolist() == [3.0, 2.0]


def test_an_empty_run_reads_as_empty(tmp_path):
    path = tmp_path / "empty.h5"
    w = LogWriter(path)
    w.start(RunInfo("e", {}, CONFIG, "h", 0, str(path), 1, 1))
    w.trials([])
    w.set_status("aborted", "the avoid behaviour raised ValueError")
    w.release()
    log = open_log(path)
    log.check()
    assert (log.attrs["source"], log.attrs["inputs"], log.plugins) == ("", "{}", [])
    assert "sensor" not in log.attrs and "code_hash" not in log.attrs
    assert (log.status, log.complete) == ("aborted", False)
    assert log.failure == "the avoid behaviour raised ValueError"
    assert log.trial_indices() == [] and log.summary().dtype.names == ("trial",)
    assert len(log.summary()) == 0 and not log.has("summary")
    with pytest.raises(InputError, match="no trial 0; it has no finished trials"):
        log.trial(0)
    with pytest.raises(InputError) as e:
        log.stage("cluster")
    assert str(e.value) == f"{path}: cluster: the log has no 'cluster' stage (status: aborted)"
    with pytest.raises(InputError) as e:
        log.interpreter_state()
    assert str(e.value) == (f"{path}: cluster: the log has no fitted situations (no "
                            "/cluster/state); was the cluster stage run?")
    assert not os.path.exists(str(path) + ".lock")


def test_a_missing_trial_lists_the_trials_there_are(written):
    with pytest.raises(InputError, match=r"has no trial 5; it has \[0, 1\]") as e:
        open_log(written).trial(5)
    assert (e.value.file, e.value.key) == (str(written), "trials")


@pytest.mark.parametrize(("name", "value", "words"), [
    ("plugins", "{not json", "not valid JSON"),
    ("worlds", "[1]", "should hold a JSON dict, got list"),
    ("config", "x = = 1", "not valid TOML"),
    ("sensor", '{"name": "ring"}', "not a sensor spec"),
])
def test_a_damaged_root_attribute_is_named(written, tmp_path, name, value, words):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(written.read_bytes())
    with h5py.File(bad, "a") as f:
        f.attrs[name] = value
    log = open_log(bad)
    with pytest.raises(InputError, match=words) as e:
        getattr(log, name)
    assert (e.value.file, e.value.key) == (str(bad), name)


def test_a_log_without_a_config_says_what_it_expected(written, tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(written.read_bytes())
    with h5py.File(bad, "a") as f:
        del f.attrs["config"]
    with pytest.raises(InputError, match="no config .*root attribute 'config'"):
        _ = open_log(bad).config


def test_a_log_without_a_sensor_spec_reads_it_from_the_config_sensor(written, tmp_path):
    old = tmp_path / "old.h5"
    old.write_bytes(written.read_bytes())
    with h5py.File(old, "a") as f:
        del f.attrs["sensor"]
        f.attrs["config"] = '[sensor]\ncomponent = "pioneer-sonar"\nmax_range = 2.0\n'
    s = open_log(old).sensor
    assert s.name == "pioneer-sonar" and s.max_range == 2.0 and s.unit == "m"
    assert s.angles_deg.tolist() == [90.0, 50.0, 30.0, 10.0, -10.0, -30.0, -50.0, -90.0]


@pytest.mark.parametrize(("attrs", "words"), [
    ({"schema": "other"}, r"not a sitframe log \(root attribute schema is 'other'"),
    ({"schema": None}, "not a sitframe log"),
    ({"schema_version": 2}, "unknown log schema version 2; this sitframe reads version 1"),
    ({"schema_version": True}, "unknown log schema version True"),
    ({"schema_version": "1"}, "unknown log schema version '1'"),
])
def test_a_file_that_is_not_this_kind_of_log_is_refused(tmp_path, attrs, words):
    path = tmp_path / "x.h5"
    with h5py.File(path, "w") as f:
        f.attrs["schema"], f.attrs["schema_version"] = "sitframe-log", 1
        for k, v in attrs.items():
            if v is None:
                del f.attrs[k]
            else:
                f.attrs[k] = v
    with pytest.raises(InputError, match=words) as e:
        open_log(path)
    assert e.value.file == str(path)


def test_a_missing_or_non_hdf5_file_is_refused(tmp_path):
    with pytest.raises(InputError, match="log file not found"):
        open_log(tmp_path / "none.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(InputError, match="not an HDF5 file"):
        open_log(tmp_path / "text.h5")


def test_a_second_writer_is_refused_and_the_lock_is_released(tmp_path):
    path = tmp_path / "run.h5"
    lock = str(path) + ".lock"
    fd = os.open(lock, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)  # another process's writer
    try:
        with pytest.raises(InputError, match="another sitframe process is writing this log") \
                as e:
            LogWriter(path).start(_info(path))
        assert (e.value.file, e.value.key) == (str(path), "--out")
    finally:
        os.close(fd)
    assert not path.exists()
    w = LogWriter(path)
    w.start(_info(path))
    assert os.path.exists(lock)
    w.release()
    assert not os.path.exists(lock)


def test_a_full_disk_is_one_clear_refusal_and_keeps_the_published_log(tmp_path, monkeypatch):
    path = tmp_path / "run.h5"
    w = LogWriter(path)
    w.start(_info(path))
    before = path.read_bytes()

    def full(*_a):
        raise OSError(errno.ENOSPC, "No space left on device")

    with monkeypatch.context() as m:
        m.setattr(L, "write_bytes", full)
        with pytest.raises(InputError) as e:
            w.stage("collect", {"samples": np.ones(3)})
    assert e.value.message.startswith(f"the disk is full: {tmp_path} has ")
    assert "the log holds no finished trial yet: make space there and run the command " \
        "again" in e.value.message
    assert (e.value.file, e.value.key) == (str(path), None)

    def denied(*_a):
        raise OSError(errno.EACCES, "Permission denied")

    def odd(*_a):
        raise OSError("device went away")  # no errno, no strerror

    for fault, why in ((denied, "Permission denied"), (odd, "device went away")):
        with monkeypatch.context() as m:
            m.setattr(L, "write_bytes", fault)
            with pytest.raises(InputError) as e:
                w.set_status("complete")
        assert e.value.message.startswith(f"cannot write the log ({why}); ")
    assert path.read_bytes() == before and not list(tmp_path.glob("*.part"))
    w.release()


def test_the_code_fingerprint_follows_the_code_and_the_plugins(tmp_path):
    plugin = tmp_path / "my_plugin.py"
    plugin.write_text("X = 1\n")
    info = {"name": "mine", "distribution": None, "version": None, "file": str(plugin)}
    base = code_fingerprint()
    assert len(base) == 64 and base == code_fingerprint() == code_fingerprint([])
    one = code_fingerprint([info])
    assert one != base and one == code_fingerprint([info])
    plugin.write_text("X = 2\n")  # the plugin's source changed
    assert code_fingerprint([info]) not in (one, base)
    pkg = {"name": "pkg", "distribution": "pkg", "version": "2.0", "file": ""}
    others = [{**pkg, "version": "1.0"}, {**pkg, "name": "pkg2"}, {**pkg, "distribution": "p"}]
    assert len({code_fingerprint([pkg])} | {code_fingerprint([o]) for o in others}) == 4
    gone = [{**info, "file": str(tmp_path / f"gone{i}.py")} for i in (1, 2)]  # unreadable:
    assert len({code_fingerprint([g]) for g in gone} | {base, one}) == 4  # counted by name


def test_the_code_fingerprint_covers_every_source_file_of_sitframe_and_its_plugins(
        tmp_path, monkeypatch):
    """What the fingerprint reads: every ``*.py`` below the folders of the ``sitframe`` and
    ``sitframe.plugins`` packages (here two stand-in folders), nothing else."""
    import importlib.util
    from types import SimpleNamespace

    real = importlib.util.find_spec
    folders = {"sitframe": tmp_path / "core", "sitframe.plugins": tmp_path / "plug"}
    for f in folders.values():
        (f / "sub").mkdir(parents=True)
        (f / "a.py").write_text("A = 1\n")
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: SimpleNamespace(
        origin=str(folders[name] / "__init__.py"), submodule_search_locations=[
            str(folders[name]), str(tmp_path)]) if name in folders else real(name, *a))
    (tmp_path / "checkout.py").write_text("# in a source checkout sitframe's __path__ also "
                                          "holds the root, whose other files are not sitframe")
    seen = [code_fingerprint()]
    for f in folders.values():
        for edit in ("a.py", "sub/b.py"):  # an edited file, a new file in a subfolder
            (f / edit).write_text(f"# {len(seen)}\n")
            seen.append(code_fingerprint())
        (f / "notes.txt").write_text("not code")
        assert code_fingerprint() == seen[-1]
    (tmp_path / "checkout.py").write_text("# changed")
    assert code_fingerprint() == seen[-1]
    assert len(set(seen)) == 5

def test_a_flipped_byte_in_the_data_is_an_input_error_not_a_wrong_number(written, tmp_path):
    with h5py.File(written, "r") as f:  # every dataset carries its checksum
        names = []
        f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset)
                     and not o.fletcher32 else None)
        assert names == []
        info = f["trials/0001/pose"].id.get_chunk_info(0)
    data = bytearray(written.read_bytes())
    data[info.byte_offset + info.size // 2] ^= 0x40
    bad = tmp_path / "bad.h5"
    bad.write_bytes(bytes(data))
    log = open_log(bad)  # the structure is intact
    assert log.trial(0).index == 0
    for read in (lambda: log.trial(1), log.check):
        with pytest.raises(InputError, match="cannot read the log .*corrupted") as e:
            read()
        assert e.value.file == str(bad) and "\n" not in str(e.value)


def test_an_output_logged_without_action_values_is_left_out(written, tmp_path):
    part = tmp_path / "part.h5"
    part.write_bytes(written.read_bytes())
    with h5py.File(part, "a") as f:
        del f["trials/0000/behaviours/avoid/actions/heading"]
    assert list(open_log(part).trial(0).learned_policy("avoid").outputs) == ["speed", "turn"]


def test_the_tables_as_data_frames(written):
    pytest.importorskip("pandas")
    log = open_log(written)
    s = log.summary_frame()
    assert s["trial"].tolist() == [0, 1] and s["converged"].tolist() == [False, True]
    one = log.iterations_frame([1])
    assert one["trial"].tolist() == [1] * 4 and one["iteration"].tolist() == [0, 1, 2, 3]
    assert one["x"].tolist() == _trial(1).arrays["pose"][:4, 0].tolist()
    assert log.iterations_frame()["trial"].tolist() == [0] * 4 + [1] * 4


def _unpacked(path, trials=(0, 1)) -> LogWriter:
    w = LogWriter(path)
    w.start(_info(path))
    w.trials([_trial(k) for k in trials])
    return w


def test_a_resumed_run_keeps_its_trials_in_their_own_files_until_it_ends(tmp_path):
    path = tmp_path / "run.h5"
    _unpacked(path).release()  # killed: trials 0 and 1 in their own files
    folder = L.shard_folder(path)
    w = LogWriter(path)
    w.start(_info(path), resume=True)
    assert sorted(p.name for p in folder.iterdir()) == ["0000.h5", "0001.h5"]
    assert open_log(path).status == "running"
    w.trial(_trial(2))
    w.set_status("aborted")  # the end of a run packs it ...
    w.release()
    assert not folder.exists()
    w = LogWriter(path)  # ... and a resumed packed log mixes copied and linked trials
    w.start(_info(path), resume=True)
    w.trial(_trial(3))
    assert sorted(p.name for p in folder.iterdir()) == ["0003.h5"]
    w.set_status("complete")
    w.release()
    assert not folder.exists()
    log = open_log(path)
    log.check()
    assert log.trial_indices() == [0, 1, 2, 3]
    assert log.trial(3).arrays["pose"].tobytes() == _trial(3).arrays["pose"].tobytes()
    assert log.summary()["trial"].tolist() == [0, 1, 2, 3]


def test_packing_a_renamed_log_leaves_what_else_is_in_its_trial_folder(tmp_path):
    path = tmp_path / "run.h5"
    _unpacked(path).release()
    renamed = tmp_path / "renamed.h5"
    path.rename(renamed)  # its links still name run.h5.trials/
    (L.shard_folder(path) / "notes.txt").write_text("mine")
    w = LogWriter(renamed)
    w.pack()
    w.release()
    assert [p.name for p in L.shard_folder(path).iterdir()] == ["notes.txt"]
    assert open_log(renamed).trial(1).index == 1


def test_a_trial_linked_to_another_trials_file_is_refused(tmp_path):
    path = tmp_path / "run.h5"
    _unpacked(path, (0, 1, 2)).release()
    with h5py.File(path, "a") as f:
        del f["trials/0001"]
        f["trials/0001"] = h5py.ExternalLink("run.h5.trials/0002.h5", "/")
    with pytest.raises(InputError, match="expected the trial's own file") as e:
        open_log(path).trial_indices()
    assert (e.value.file, e.value.key) == (str(path), "trials/0001")


def test_trials_that_are_not_a_group_are_named(written, tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(written.read_bytes())
    with h5py.File(bad, "a") as f:
        del f["trials"]
        f["trials"] = np.zeros(2)
    with pytest.raises(InputError, match="expected a group of trial groups") as e:
        open_log(bad).trial_indices()
    assert (e.value.file, e.value.key) == (str(bad), "trials")


def test_a_sensor_read_from_an_old_logs_config_names_what_is_wrong(written, tmp_path):
    old = tmp_path / "old.h5"
    old.write_bytes(written.read_bytes())
    with h5py.File(old, "a") as f:
        del f.attrs["sensor"]
        f.attrs["config"] = '[experiment]\nname = "rt"\n'  # no [sensor]: the default sonar
    s = open_log(old).sensor
    assert (s.name, s.max_range, len(s.angles_deg)) == ("pioneer-sonar", 3.0, 8)
    with h5py.File(old, "a") as f:
        f.attrs["config"] = '[sensor]\nmax_range = -1.0\n'
    with pytest.raises(InputError, match="max_range") as e:
        _ = open_log(old).sensor
    assert e.value.file == str(old) and e.value.key.startswith("sensor")


def test_the_next_writer_removes_what_a_killed_writer_left_and_nothing_else(tmp_path):
    path = tmp_path / "run.h5"
    _unpacked(path).release()
    folder = L.shard_folder(path)
    dead = LogWriter(path)  # a writer killed inside its transactions leaves scratch files
    left = [dead._scratch(), dead._scratch(folder)]
    dead.release()
    assert re.fullmatch(r"run\.h5\.[a-z0-9_]{8}\.part", left[0].name) and left[0].parent == tmp_path
    assert re.fullmatch(r"\.[a-z0-9_]{8}\.part", left[1].name) and left[1].parent == folder
    (tmp_path / "run.h5.part").write_text("")  # (the name older versions used)
    (folder / "0007.h5").write_text("")  # written, never linked
    keep = ["run.h5.notes.part", "other.h5.part", "run.h5.bak", "notes.h5"]
    for name in keep:
        (tmp_path / name).write_text("")
    (folder / "readme.txt").write_text("")
    w = LogWriter(path)
    w.start(_info(path), resume=True)
    assert open_log(path).status == "running"
    assert sorted(p.name for p in folder.iterdir()) == ["0000.h5", "0001.h5", "readme.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["run.h5", "run.h5.trials", "run.h5.lock", *keep])
    w.release()


def test_a_log_in_a_new_folder_and_its_lock_file(tmp_path):
    path = tmp_path / "a" / "b" / "run.h5"
    w = LogWriter(path)
    w.start(_info(path))
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(str(path) + ".lock").st_mode) == 0o644 & ~umask
    other = LogWriter(tmp_path / "other.h5")
    other.start(_info(tmp_path / "other.h5"))
    w.release()  # releases this log only
    with pytest.raises(InputError, match="another sitframe process"):
        _second_writer(tmp_path / "other.h5")
    os.remove(str(tmp_path / "other.h5") + ".lock")  # removed by hand: release still works
    other.release()
    LogWriter(tmp_path / "never.h5").release()  # a writer that never wrote


def _second_writer(path) -> None:
    """Start a writer of ``path`` in another process (a lock held here refuses it there)."""
    import subprocess
    import sys

    code = ("import sys; from sitframe.logs.writer import lock_log\n"
            "try:\n    lock_log(sys.argv[1])\nexcept Exception as e:\n    print(e); sys.exit(2)")
    r = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True)
    if r.returncode:
        raise InputError(r.stdout.strip())


def test_a_lock_file_that_cannot_be_made_is_one_clear_refusal(tmp_path):
    (tmp_path / "file").write_text("")
    bad = tmp_path / "file" / "run.h5"
    with pytest.raises(InputError) as e:
        LogWriter(bad).start(_info(bad))
    assert str(e.value) == (f"{bad}: --out: cannot create the log: File exists (its lock "
                            "file 'run.h5.lock')")
    target = tmp_path / "target"
    target.write_text("precious")
    os.symlink(target, tmp_path / "run.h5.lock")  # planted: never opened through
    with pytest.raises(InputError, match=r"cannot create the log: .*'run\.h5\.lock'"):
        LogWriter(tmp_path / "run.h5").start(_info(tmp_path / "run.h5"))
    assert target.read_text() == "precious" and not (tmp_path / "run.h5").exists()


@pytest.mark.parametrize(("change", "words"), [
    (lambda f: f.__setitem__("trials/0001", h5py.ExternalLink("run.h5.trials/0001.h5", "/x")),
     "links to 'run.h5.trials/0001.h5:/x'; expected the trial's own file "
     "<log>.trials/0001.h5 beside the log"),
    (None, "trial 1 is in 'run.h5.trials/0001.h5', which is missing: a log still being written "
           "(or killed) is its .h5 file and the folder 'run.h5.trials' beside it; move them "
           "together, or pack the log into one file first (sitframe pack LOG)"),
    ("symlink", "'run.h5.trials/0001.h5' is not a regular file (expected the trial's own HDF5 "
                "file)"),
])
def test_a_trial_file_that_is_not_the_trials_own_is_named(tmp_path, change, words):
    path = tmp_path / "run.h5"
    _unpacked(path).release()
    shard = L.shard_folder(path) / "0001.h5"
    if change == "symlink":
        shard.rename(tmp_path / "elsewhere.h5")
        os.symlink(tmp_path / "elsewhere.h5", shard)
    elif change is None:
        shard.unlink()
    else:
        with h5py.File(path, "a") as f:
            del f["trials/0001"]
            change(f)
    with pytest.raises(InputError) as e:
        open_log(path).trial(1)
    assert str(e.value) == f"{path}: trials/0001: {words}"


def test_the_summary_kept_by_appending_is_the_table_rebuilt_from_every_trial(tmp_path):
    """Trials in order, a batch out of order, a trial written again, and one with a new
    summary key: one row per trial, in trial order, as rebuilt from the trials."""
    path = tmp_path / "run.h5"
    w = _unpacked(path, (0,))
    extra = _trial(5)
    extra.summary["late"] = 1.5
    for batch in ([_trial(1)], [_trial(3), _trial(2)], [_trial(3)], [_trial(4)], [extra]):
        w.trials(batch)
        with h5py.File(path, "a") as f:
            kept = f["summary"][()]
            L._write_summary(f)
            rebuilt = f["summary"][()]
        assert kept.dtype == rebuilt.dtype and kept.tobytes() == rebuilt.tobytes()
    assert kept["trial"].tolist() == [0, 1, 2, 3, 4, 5]
    assert np.isnan(kept["late"][:5]).all() and kept["late"][5] == 1.5
    w.release()


def test_the_writer_refuses_a_folder_as_log_and_a_symlinked_trial_folder(tmp_path):
    (tmp_path / "dir.h5").mkdir()
    bad = LogWriter(tmp_path / "dir.h5")
    with pytest.raises(InputError) as e:
        bad.start(_info(tmp_path / "dir.h5"))
    assert str(e.value) == f"{tmp_path / 'dir.h5'}: --out: cannot create the log: Is a directory"
    bad.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.h5"]  # no scratch file left
    path = tmp_path / "run.h5"
    (tmp_path / "elsewhere").mkdir()
    os.symlink(tmp_path / "elsewhere", L.shard_folder(path))
    w = LogWriter(path)
    w.start(_info(path))
    with pytest.raises(InputError) as e:
        w.trial(_trial(0))
    assert str(e.value) == (f"{path}: --out: 'run.h5.trials' beside the log is a symlink; "
                            "refusing to write the log's trials through it")
    assert list((tmp_path / "elsewhere").iterdir()) == []
    w.release()
    a = open_log(path).attrs
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d{4}", a["created"]), a["created"]


@pytest.mark.parametrize(("edit", "key", "words"), [
    (lambda f: f["cluster/state/centers"].attrs.create("x", 0) or f.__delitem__(
        "cluster/state/centers") or f.__setitem__("cluster/state/centers", np.full((2, 3), np.nan)),
     "cluster/state/centers", "expected a finite (c, d) array of centres, got shape (2, 3), "
                              "dtype float64"),
    (lambda f: f.__delitem__("cluster/state/centers") or f.__setitem__(
        "cluster/state/centers", np.ones(3)),
     "cluster/state/centers", "expected a finite (c, d) array of centres, got shape (3,)"),
    (lambda f: f.__delitem__("cluster/state/centers") or f.__setitem__(
        "cluster/state/centers", np.array([["a", "b", "c"]] * 2, dtype=h5py.string_dtype())),
     "cluster/state/centers", "expected a finite (c, d) array of centres"),
    (lambda f: f.__delitem__("cluster/state/centers") or f.__setitem__(
        "cluster/state/centers", np.ones((3, 3))),
     "trials/0000/memberships", "has shape (4, 2), which does not fit the fitted centres' "
                                "shape (3, 3)"),
    (lambda f: f.__delitem__("cluster/state/centers") or f.__setitem__(
        "cluster/state/centers", np.ones((2, 4))),
     "trials/0000/reading", "has shape (4, 3), which does not fit the fitted centres' shape "
                            "(2, 4)"),
    (lambda f: f["cluster/state"].attrs.create("capacity", 5),
     "trials/0000/memberships", "which does not fit the fitted centres' shape (5, 3)"),
    (lambda f: f["trials/0001"].move("reading", "sonar") or f.__delitem__(
        "cluster/state/centers") or f.__setitem__("cluster/state/centers", np.ones((2, 5))),
     "trials/0000/reading", "(2, 5)"),
    (lambda f: f.__delitem__("trials/0001") or f.__setitem__("trials/0001", np.ones(2)),
     "trials/0001", "expected a trial group, got a dataset"),
    (lambda f: f.__delitem__("trials") or f.__setitem__("trials", np.ones(2)),
     "trials", "expected a group of trial groups, got a dataset"),
    (lambda f: f["trials/0000/behaviours/avoid/policy/turn"].__setitem__(
        (), np.array([0, 2], np.int16)) or None,
     "trials/0000/behaviours/avoid/policy/turn", "expected action indices in 0..1, got [0, 2]"),
    (lambda f: f["trials/0000/behaviours/avoid/policy"].__delitem__("turn") or f[
        "trials/0000/behaviours/avoid/policy"].__setitem__("turn", np.array([-1, 0])),
     "trials/0000/behaviours/avoid/policy/turn", "got [-1, 0]"),
    (lambda f: f["trials/0000/behaviours/avoid/policy"].__delitem__("turn") or f[
        "trials/0000/behaviours/avoid/policy"].__setitem__("turn", np.array([0.0, 1.0])),
     "trials/0000/behaviours/avoid/policy/turn", "got [0.0, 1.0]"),
])
def test_a_damaged_layout_is_named_by_check(written, tmp_path, edit, key, words):
    """What readers index with: trial groups, finite (c, d) centres that fit the trials'
    memberships (c) and readings (d), policies that index existing actions."""
    bad = tmp_path / "bad.h5"
    bad.write_bytes(written.read_bytes())
    with h5py.File(bad, "a") as f:
        edit(f)
    with pytest.raises(InputError) as e:
        open_log(bad).check()
    assert e.value.file == str(bad) and e.value.key == key and words in e.value.message, \
        str(e.value)


def test_an_intact_log_and_its_edge_cases_pass_check(written, tmp_path):
    ok = tmp_path / "ok.h5"
    ok.write_bytes(written.read_bytes())
    with h5py.File(ok, "a") as f:
        f["cluster/state"].attrs["capacity"] = 2  # evolving situations: as many id slots
        del f["trials/0000/behaviours/avoid/actions/turn"]  # an output without actions
        del f["trials/0001/behaviours/avoid/policy"]
        f["trials/0001/behaviours/avoid/policy"] = np.zeros(0, np.int16)  # not a group
    open_log(ok).check()
    path = tmp_path / "run.h5"
    _unpacked(path, (0, 1)).release()
    open_log(path).check()  # the trials in their own files are read as well
    with h5py.File(L.shard_folder(path) / "0001.h5", "a") as f:
        f.attrs["index"] = 0
    with pytest.raises(InputError, match="its file holds trial 0, expected 1"):
        open_log(path).check()
