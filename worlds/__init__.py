"""Shipped world files (TOML). Load them by name with ``sitframe.world.load_world``."""
