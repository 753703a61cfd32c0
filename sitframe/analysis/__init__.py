"""Offline analysis of sitframe HDF5 logs: arrays and matplotlib figures."""
