"""sitframe: situation-based navigation behaviours for a simulated mobile robot.

Sonar readings are clustered by fuzzy c-means into fuzzy *situations*; a fuzzy
rule base maps situations to actions; fuzzy Q-learning learns that rule base
online from a reward. Every component is a pluggy plugin; every run is logged
to HDF5.
"""

from __future__ import annotations

import pluggy

__version__ = "0.1.0"

#: Decorator plugin authors use to implement a hook (``@sitframe.hookimpl``).
hookimpl = pluggy.HookimplMarker("sitframe")

__all__ = ["__version__", "hookimpl"]
