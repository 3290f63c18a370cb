"""The equivalence study: MJED against the UFL oracle, materials x meshes x states.

``study`` runs the cases and judges them; ``closed_form`` (the uniaxial closed forms),
``taylor`` (derivative checks that need no oracle) and ``ogden_tangent`` (SOFA's coaxial
Ogden tangent against the exact one) are its supporting checks.
"""
