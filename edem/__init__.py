"""Discrete element (DEM) and extended discrete element (EDEM) contact solver (SPEC 2-4)."""

__version__ = "0.1.0"
