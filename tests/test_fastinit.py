"""The per-iteration records' cheaper ``__init__`` (sitframe.sim.fastinit) builds the same
instances as the dataclass's own."""

from __future__ import annotations

import dataclasses
import inspect
import pickle
from dataclasses import dataclass

import numpy as np
import pytest

from sitframe.contract.records import Context, Proposal, StepRecord, Transition
from sitframe.sim.fastinit import slot_init
from sitframe.sim.robot import Command, StepOutcome

RECORDS = (Command, StepOutcome, Proposal, Context, Transition, StepRecord)


@dataclass(frozen=True, slots=True)
class _Plain:
    a: int
    b: float = 2.5
    c: object = None


def test_the_signature_defaults_and_instances_are_the_dataclass_own() -> None:
    fast = slot_init(dataclass(frozen=True, slots=True)(
        type("_Fast", (), {"__annotations__": dict(_Plain.__annotations__), "b": 2.5,
                           "c": None})))
    assert [p.name for p in inspect.signature(fast).parameters.values()] == ["a", "b", "c"]
    assert [p.default for p in inspect.signature(fast).parameters.values()] == \
        [p.default for p in inspect.signature(_Plain).parameters.values()]
    f, p = fast(1), _Plain(1)
    assert (f.a, f.b, f.c) == (p.a, p.b, p.c)
    assert fast(1, c="x") == fast(1, 2.5, "x") and hash(fast(1)) == hash(fast(1))
    assert repr(fast(3)).endswith("(a=3, b=2.5, c=None)")
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.a = 2  # type: ignore[misc]
    with pytest.raises(TypeError):
        fast()  # type: ignore[call-arg]


@pytest.mark.parametrize("cls", RECORDS, ids=lambda c: c.__name__)
def test_the_records_keep_their_fields_in_order(cls: type) -> None:
    names = [f.name for f in dataclasses.fields(cls)]
    assert list(inspect.signature(cls).parameters) == names
    assert cls.__init__.__qualname__ == f"{cls.__qualname__}.__init__"


def test_records_still_check_pickle_and_replace() -> None:
    with pytest.raises(ValueError, match="finite"):
        Command(float("nan"), 0.15)  # (__post_init__ still runs)
    cmd = Command(10.0)
    assert cmd.speed_m_s == 0.15 and pickle.loads(pickle.dumps(cmd)) == cmd
    assert dataclasses.replace(cmd, speed_m_s=0.2) == Command(10.0, 0.2)
    pose = np.zeros(3)
    out = StepOutcome(pose, pose, False, np.full(2, np.nan), pose, 0.1, 5.0)
    assert (out.backoff_m, out.recovery_turn_deg) == (0.0, 0.0)
    back = pickle.loads(pickle.dumps(out))
    assert back.distance_m == 0.1 and back.collided is False
    assert Proposal(5.0) == Proposal(5.0, None, None)


def test_only_frozen_slotted_dataclasses() -> None:
    with pytest.raises(TypeError, match="frozen, slotted"):
        slot_init(dataclass(type("_Open", (), {"__annotations__": {"a": "int"}})))
