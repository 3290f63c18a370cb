"""Readers for mesh file formats that keep the file's own node numbering.

meshio (used for the other formats) renumbers nodes in file order and drops their ids; the
readers here return the ids as written, so that a user can compare node by node.
"""
