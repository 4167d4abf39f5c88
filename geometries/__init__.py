"""Geometry builders (gmsh) and mesh import (meshio) for the discrete and FE models (docs/method.md#8-built-in-geometries)."""
