"""Shipped world files (TOML). Load them by name with ``sitframe.sim.world.load_world``."""
