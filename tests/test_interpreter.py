"""The FCM situation interpreter plugin: fit, live memberships, logged state."""

from __future__ import annotations

import numpy as np
import pytest

from sitframe.plugins.fcm_interpreter import FCMInterpreter
from sitframe.situations.fcm import memberships


def _readings(n: int = 400, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.05, 3.0, (6, 8))
    X = base[rng.integers(0, 6, n)] * rng.uniform(0.8, 1.2, (n, 8))
    return np.clip(X, 0.0, 3.0)


@pytest.mark.parametrize("transform", ["range", "log", "inverse"])
def test_memberships_use_the_clustering_space_and_survive_the_log(transform):
    X = _readings()
    a = FCMInterpreter(c=5, trials=3, transform=transform, offset=0.1)
    fit = a.fit(X, np.random.default_rng(1))
    assert fit["trial_centers"].shape == (3, 5, 8)
    state = a.state()
    # logged centres are in metres, whatever the feature space
    np.testing.assert_allclose(a.features(state["centers"]), state["feature_centers"])
    u = np.array([a.memberships(x) for x in X[:50]])
    expected = memberships(a.features(X[:50]), state["feature_centers"], 1.2)
    np.testing.assert_allclose(u, expected, atol=1e-9)
    b = FCMInterpreter(c=5, transform=transform, offset=0.1)
    b.load_state(state)
    np.testing.assert_allclose([b.memberships(x) for x in X[:50]], u)


def test_log_transform_separates_touching_from_open():
    a = FCMInterpreter(c=2, transform="log")
    touching = np.array([3.0, 3.0, 3.0, 0.02, 3.0, 3.0, 3.0, 3.0])  # one beam at 2 cm
    open_ = np.full(8, 3.0)
    roomy = np.full(8, 1.5)  # everything 1.5 m away

    def ratio(f):
        return np.linalg.norm(f(touching) - f(open_)) / np.linalg.norm(f(roomy) - f(open_))

    # In raw ranges, touching something is *closer* to open space than a roomy reading
    # is; in log space it is farther, so it cannot be mistaken for open space.
    assert ratio(lambda x: x) < 1.0 < ratio(a.features)


def test_state_of_another_transform_is_rejected():
    a = FCMInterpreter(c=3, trials=2, transform="log")
    a.fit(_readings(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="transform 'log'"):
        FCMInterpreter(c=3, transform="range").load_state(a.state())


def test_bad_transform_names_the_choices():
    with pytest.raises(ValueError, match="expected one of 'range', 'log', 'inverse'"):
        FCMInterpreter(transform="sqrt")
