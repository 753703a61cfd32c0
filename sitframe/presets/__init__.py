"""Experiment presets shipped with sitframe (TOML run configs)."""
