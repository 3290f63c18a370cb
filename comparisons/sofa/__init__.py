"""SOFA's own force fields through the checker, and the paper's speed claim timed on SOFA's code:
``study`` (``mjed-verify sofa``).
"""
