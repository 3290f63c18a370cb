"""Stage 4, the diagnosis: the mistake that explains a failed case.

``diagnose`` (verdict, errors and findings of one case), ``findings`` (what it reports),
``hypotheses`` (convention mistakes as corrections), ``frames`` (fibre-frame mistakes),
``tangent`` (which part of the tangent explains an error, a finite-difference tangent),
``variants`` (rewritten formulas), ``energy_terms`` (an energy split into its terms or evaluated
with a mistaken kinematic, for the oracle), ``term_fit`` (the terms' coefficients fitted),
``kinematics`` (kinematic mistakes), ``parameters`` (parameters exchanged or with another
value), ``refit`` (a few numbers of the energy fitted through the oracle), ``constants`` (the
exponents of J refitted), ``readings`` (the hypotheses the oracle evaluates, every one tried,
ambiguity said), ``roundoff`` (float32's signature). The diagnosis reads the judge's figures;
it never runs an engine.
"""
