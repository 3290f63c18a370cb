"""The timing study (paper, Fig. 2) and the scaling study, and what explains their figures.

``study`` sets up, measures and judges; ``protocol`` says how measurements repeat, ``methods``
which methods can be timed; ``records`` holds what is measured, ``blocks`` and ``figures`` turn
it into the report's blocks and the PNGs. ``opcount`` (operation counts) and ``bandwidth``
(this machine's memory floor) explain the times; ``hardware`` (``python -m
comparisons.timing.hardware``) measures MJED at the hardware's limit, ``gpu`` its GPU part,
and ``gpu_section`` puts those GPU figures into the report.
"""
