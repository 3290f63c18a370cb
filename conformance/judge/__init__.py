"""Stage 3, the judge: the oracle's values and how far an engine's output is from them.

``oracle`` (energy, force, stiffness from the UFL oracle), ``energy`` (the strain energy it
differentiates), ``parts`` (its stiffness split into named parts), ``compare`` (relative
errors and tolerances), ``precision`` (tolerances at single precision), ``consistency`` (is
the engine's stiffness the derivative of its own force?).
"""
