"""Exceptions of the meshes package."""

from __future__ import annotations

__all__ = ["MeshReadError"]


class MeshReadError(ValueError):
    """A mesh file could not be turned into linear tetrahedra; the message names the file."""
