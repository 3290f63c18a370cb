"""Stage 4, the diagnosis: the mistake that explains a failed case.

``diagnose`` (verdict, errors and findings of one case), ``findings`` (what it reports),
``hypotheses`` (convention mistakes as corrections), ``frames`` (fibre-frame mistakes),
``tangent`` (which part of the tangent explains an error), ``variants`` (which energy the
engine computes). The diagnosis reads the judge's figures; it never runs an engine.
"""
