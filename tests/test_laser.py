"""The laser scanner plugin, and situations / analysis for beam layouts other than the sonar."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from geometry_reference import raycast_reference
from helpers import run_config, small_config

from sitframe import InputError
from sitframe import analysis as A
from sitframe.cli.app import main
from sitframe.plugins.laser import LaserScanner, sitframe_sensors
from sitframe.plugins.sonar import PIONEER_ANGLES_DEG as PIONEER
from sitframe.sim.world import load_world, parse_world
from sitframe.situations.clustering import describe_prototype

# A 6 x 1.4 m corridor, closed at both ends.
CORRIDOR = parse_world("""
name = "corridor"
[robot]
start = [3, 0.7, 0]
[[walls]]
points = [[0, 0], [6, 0], [6, 1.4], [0, 1.4], [0, 0]]
""")


def test_layouts() -> None:
    assert LaserScanner().angles_deg.tolist() == list(np.arange(-90.0, 91.0, 12.0))
    ring = LaserScanner(fov_deg=360, beams=16).angles_deg
    assert ring[0] == -180 and ring.max() < 180 and np.allclose(np.diff(ring), 22.5)
    assert LaserScanner(beams=1).angles_deg.tolist() == [0.0]
    turned = LaserScanner(fov_deg=90, beams=3, angle_offset_deg=180).angles_deg
    assert turned.tolist() == [135.0, -180.0, -135.0]  # kept in [-180, 180)
    assert not LaserScanner().angles_deg.flags.writeable


@pytest.mark.parametrize("kwargs", [{}, {"fov_deg": 360, "beams": 37}, {"fov_deg": 270, "beams": 5,
                                    "angle_offset_deg": 30, "max_range": 2.0}])
def test_matches_the_brute_force_reference(kwargs: dict) -> None:
    world = load_world("training")
    laser = LaserScanner(**kwargs)
    segs = world.segment_set.segments
    rng = np.random.default_rng(7)
    reach = laser.max_range + laser.robot_radius
    for _ in range(25):
        pose = world.random_free_pose(rng)
        got = laser.read(world, pose, rng)
        rays = np.radians(laser.angles_deg) + pose[2]
        # bracket the fast cast by the reference with hit tolerances of +-1e-9 m
        lo, hi = (raycast_reference(pose[:2], rays, segs, reach, tol=t) for t in (1e-9, -1e-9))
        expect_lo = np.where(lo >= reach, laser.max_range, lo - laser.robot_radius)
        expect_hi = np.where(hi >= reach, laser.max_range, hi - laser.robot_radius)
        assert got.shape == (laser.beams,)
        assert np.all(got >= np.clip(expect_lo, 0, None) - 1e-7)
        assert np.all(got <= np.clip(expect_hi, 0, laser.max_range) + 1e-7)


def test_ranges_from_the_rim_and_bind() -> None:
    from sitframe import RunContext, SensorSpec
    from sitframe.sim.robot import RobotParams

    laser = LaserScanner(fov_deg=360, beams=4)  # behind, right, ahead, left
    pose = np.array([3.0, 0.7, 0.0])
    np.testing.assert_allclose(laser.read(CORRIDOR, pose, None), [2.85, 0.55, 2.85, 0.55])
    run = RunContext(RobotParams(radius=0.2), SensorSpec("laser", laser.angles_deg, 4.0), (),
                     None, {}, 0, 1, 0.15)
    laser.bind(run)
    np.testing.assert_allclose(laser.read(CORRIDOR, pose, None), [2.8, 0.5, 2.8, 0.5])
    fixed = LaserScanner(fov_deg=360, beams=4, robot_radius=0.0)
    fixed.bind(run)  # an explicit robot_radius wins
    np.testing.assert_allclose(fixed.read(CORRIDOR, pose, None), [3.0, 0.7, 3.0, 0.7])
    # nothing within max_range reads exactly max_range
    assert LaserScanner(max_range=1.0).read(CORRIDOR, pose, None)[8] == 1.0


def test_noise_and_dropout_are_reproducible_and_absent_when_off() -> None:
    pose = np.array([3.0, 0.7, 0.2])
    clean = LaserScanner(fov_deg=360, beams=64)
    rng = np.random.default_rng(1)
    state = rng.bit_generator.state
    a = clean.read(CORRIDOR, pose, rng)
    assert rng.bit_generator.state == state  # no option on: the generator is not touched
    noisy = LaserScanner(fov_deg=360, beams=64, noise_std=0.05, dropout=0.2)
    b1, b2 = (noisy.read(CORRIDOR, pose, np.random.default_rng(42)) for _ in range(2))
    np.testing.assert_array_equal(b1, b2)
    assert not np.array_equal(b1, noisy.read(CORRIDOR, pose, np.random.default_rng(43)))
    dropped = (b1 == noisy.max_range) & (a < noisy.max_range)
    assert 0 < dropped.sum() < 64
    kept = ~dropped & (a < noisy.max_range - 0.3)
    assert 0 < np.abs(b1[kept] - a[kept]).max() < 0.3
    assert np.all((b1 >= 0) & (b1 <= noisy.max_range))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"fov_deg": 0}, "fov_deg"), ({"fov_deg": 400}, "fov_deg"), ({"beams": 0}, "beams"),
     ({"beams": 2.5}, "beams"), ({"beams": 10**6}, "beams"), ({"max_range": -1}, "max_range"),
     ({"robot_radius": float("nan")}, "robot_radius"), ({"noise_std": -0.1}, "noise_std"),
     ({"dropout": 1.5}, "dropout"), ({"angle_offset_deg": "left"}, "angle_offset_deg"),
     ({"beams": True}, "beams")],
)
def test_bad_params_are_one_input_error_naming_the_parameter(kwargs: dict, name: str) -> None:
    with pytest.raises(InputError) as exc:
        LaserScanner(**kwargs)
    assert exc.value.key == name and "expected" in str(exc.value)


def test_registration_and_protocol() -> None:
    from sitframe.contract.components import Sensor
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager

    assert sitframe_sensors() == [LaserScanner]
    assert isinstance(LaserScanner(), Sensor)
    pm = get_plugin_manager(autoload=True)
    assert "laser" in Registry.collect(pm).names("sensor")
    assert pm.sitframe_info["laser"].origin == "entry point"


def test_bad_param_in_a_config_is_one_line(tmp_path, capsys) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(small_config() + '\n[sensor]\ncomponent = "laser"\nbeams = 0\n')
    assert main(["run", str(cfg), "--out", str(tmp_path / "bad.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "sensor.beams: expected an integer in [1, 1024], got 0" in err


# ------------------------------------------------------------------- situations


def test_pioneer_labels_do_not_depend_on_beam_order_or_turns() -> None:
    rng = np.random.default_rng(0)
    a = np.array(PIONEER)
    for _ in range(300):
        v = rng.uniform(0.2, 3.0, 8)
        label = describe_prototype(v, PIONEER)
        assert describe_prototype(v[::-1], a[::-1]) == label
        assert describe_prototype(v, a + 360) == label
    assert describe_prototype([0.7, 1.0, 1.5, 3.0, 3.0, 1.5, 1.0, 0.7], PIONEER) == "corridor"
    assert describe_prototype([0.5, 0.6, 0.7, 0.6, 0.6, 0.7, 0.6, 0.5], PIONEER) == "dead end"


@pytest.mark.parametrize(("pose", "ring", "laser"), [
    ([3.0, 0.7, 0.0], "corridor", "corridor"),              # along the corridor
    ([5.25, 0.7, 0.0], "dead end", "dead end"),             # facing its end
    ([3.0, 0.7, np.pi / 2], "obstacle ahead", "obstacle ahead"),  # facing a side wall
    ([3.0, 0.4, 0.0], "corridor", "corridor"),              # 0.25 / 0.85 m from the walls
    ([3.0, 0.3, 0.0], "wall on right", "wall on right"),    # the left wall 0.95 m away: open
])
def test_describe_any_layout(pose, ring, laser) -> None:
    p = np.array(pose)
    for sensor, want in ((LaserScanner(fov_deg=360, beams=16), ring), (LaserScanner(), laser)):
        assert describe_prototype(sensor.read(CORRIDOR, p, None), sensor.angles_deg) == want


def test_describe_never_claims_what_the_layout_cannot_see() -> None:
    ring = LaserScanner(fov_deg=360, beams=16).angles_deg
    v = np.full(16, 4.0)
    assert describe_prototype(v, ring) == "open space"
    v[ring == -180] = 0.3  # only straight behind: not "wall on right"
    assert describe_prototype(v, ring) == "obstacle behind"
    front = LaserScanner(fov_deg=60, beams=5).angles_deg  # sees neither side
    assert describe_prototype(np.full(5, 4.0), front) == "nothing close in view"
    assert describe_prototype([4, 4, 0.3, 4, 4], front) == "front blocked"
    back = LaserScanner(fov_deg=90, beams=4, angle_offset_deg=180).angles_deg
    assert describe_prototype([0.5, 4, 4, 4], back) == "obstacle behind"
    # any layout and any ranges: a non-empty description, never an exception
    rng = np.random.default_rng(3)
    for _ in range(300):
        d = int(rng.integers(1, 40))
        label = describe_prototype(rng.uniform(0, 4, d), rng.uniform(-720, 720, d))
        assert isinstance(label, str) and label


# ------------------------------------------------------------------- runs and analysis


def _laser_config(name: str, **sensor: object) -> str:
    table = "".join(f"{k} = {v}\n" for k, v in sensor.items())
    # wander samples too: the collect stage's reflex must work with any layout
    return (small_config(name=name, trials=1, iterations=200)
            .replace("[collect]\n", '[collect]\nmode = "both"\nwander_samples = 40\n')
            + f'\n[sensor]\ncomponent = "laser"\n{table}')


@pytest.mark.parametrize(("sensor", "layout"), [({}, "arc"), ({"fov_deg": 360}, "ring")])
def test_cli_run_and_analyse_with_the_laser(tmp_path, capsys, sensor, layout) -> None:
    _, out = run_config(tmp_path, _laser_config(f"laser-{layout}", **sensor), "laser.h5")
    log = A.as_log(out)
    spec = log.sensor
    assert spec.name == "laser" and spec.dim == 16 and spec.max_range == 4.0
    assert spec.angles_deg.tolist() == LaserScanner(**sensor).angles_deg.tolist()
    assert log.trial(0).arrays["reading"].shape == (200, 16)
    assert np.asarray(log.stage("collect")["samples"]).shape[1] == 16
    labels = A.situation_labels(log, numbered=False)
    assert len(labels) == 6 and all(labels)
    # a log written before the spec was logged: the [sensor] table's plugin gives it
    with h5py.File(out, "r+") as f:
        del f.attrs["sensor"]
    old = A.as_log(out).sensor
    assert old.name == "laser" and old.max_range == 4.0
    assert old.angles_deg.tolist() == spec.angles_deg.tolist()
    rep = tmp_path / "rep"
    assert main(["analyse", str(out), "-o", str(rep), "--dpi", "50"]) == 0
    assert capsys.readouterr().err == ""
    assert (rep / "prototypes.png").stat().st_size > 2_000
    index = (rep / "index.md").read_text()
    assert "](prototypes.png)" in index and "16 'laser' ranges" in index
    assert "prototypes.png:" not in index  # not under "Not produced"


def test_prototype_plot_draws_the_layout() -> None:
    from sitframe.analysis.clustering_plots import plot_prototypes

    ring = LaserScanner(fov_deg=360, beams=16)
    V = np.array([ring.read(CORRIDOR, np.array(p), None) for p in ([3, 0.7, 0], [0.5, 0.7, 0])])
    fig = plot_prototypes(V, ring.angles_deg, max_range=ring.max_range)
    ax = fig.axes[1]
    assert ax.get_title() == "S2: corridor"  # with the end wall close behind
    assert fig.axes[0].get_title() == "S1: corridor, open behind"  # two corridors told apart
    assert (ax.get_thetamin(), ax.get_thetamax()) == (-180, 180)  # the whole ring is shown
    # the beams' end points sit at the layout's bearings, ranges unchanged
    dots = ax.lines[-2].get_xydata()
    np.testing.assert_allclose(np.sort(dots[:, 0]), np.radians(np.sort(ring.angles_deg)))
    behind = dots[np.argmin(dots[:, 0])]
    assert behind[1] == pytest.approx(0.35)  # back to the end wall, 0.5 - 0.15 m
    arc = plot_prototypes(V[:, 4:13], ring.angles_deg[4:13], max_range=4.0)  # -90..90
    assert (arc.axes[0].get_thetamin(), arc.axes[0].get_thetamax()) == (-100, 100)
