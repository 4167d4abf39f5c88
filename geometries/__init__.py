"""Geometry builders (gmsh) and mesh import (meshio) for the discrete and FE models (SPEC 6)."""
