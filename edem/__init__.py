"""Discrete element (DEM) and extended discrete element (EDEM) contact solver (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method, docs/method.md#4-viscoelastic-edem-thesis-chapter-6)."""

__version__ = "0.1.0"
