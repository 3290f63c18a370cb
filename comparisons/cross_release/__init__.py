"""Does the UFL oracle give the same numbers on every dolfinx release and process count?

``study`` takes and compares the snapshots (``python -m comparisons.cross_release``),
``records`` holds what the comparison measures.
"""
