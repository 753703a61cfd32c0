"""Shared fixtures. Tests that need an empty plugin manager pass ``autoload=False``."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
