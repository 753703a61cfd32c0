"""sitframe: situation-based navigation behaviours for a simulated mobile robot.

Sonar readings are clustered by fuzzy c-means into fuzzy *situations*; a fuzzy
rule base maps situations to actions; fuzzy Q-learning learns that rule base
online from a reward. Every component is a pluggy plugin; every run is logged
to HDF5.
"""

from __future__ import annotations

from pathlib import Path

import pluggy

__version__ = "0.1.0"

# Installed, ``plugins/`` and ``worlds/`` become ``sitframe.plugins`` and
# ``sitframe.worlds`` (setuptools package-dir). When this package is imported
# straight from a source checkout instead -- a notebook or ``python -c`` started
# in the repository root, or a multiprocessing forkserver whose ``sys.path``
# starts with the current directory -- map them the same way.
_checkout = Path(__file__).resolve().parent.parent
if (_checkout / "pyproject.toml").is_file() and (_checkout / "plugins" / "__init__.py").is_file():
    __path__.append(str(_checkout))  # noqa: F821 - a package's __path__ is always defined

#: Decorator plugin authors use to implement a hook (``@sitframe.hookimpl``).
hookimpl = pluggy.HookimplMarker("sitframe")

__all__ = ["__version__", "hookimpl"]
