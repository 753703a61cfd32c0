"""Arbiters: fuse behaviour proposals into one command.

``single`` passes one behaviour's proposal through (the thesis's learning
experiments run one behaviour at a time).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sitframe import hookimpl
from sitframe.records import Context, Proposal


class SingleArbiter:
    """Use the proposal of the only behaviour (error if there are several)."""

    name = "single"
    _ONE = np.ones(1)

    def __init__(self) -> None:
        pass

    def combine(self, context: Context, proposals: dict[str, Proposal]) -> tuple[Proposal, Any]:
        if len(proposals) != 1:
            raise ValueError(f"the 'single' arbiter needs exactly one behaviour, got "
                             f"{len(proposals)} ({', '.join(proposals)}); use 'cdb' or 'priority'")
        (prop,) = proposals.values()
        return prop, self._ONE


@hookimpl
def sitframe_arbiters() -> list[Any]:
    return [SingleArbiter]
