"""The liver under gravity (paper, section 4.3; Fig. 1 right and Fig. 4).

``study`` runs the three models and judges them; ``setup`` holds the models, parameters and
backends, ``organ`` and ``regions`` the user's organ mesh and its boundary nodes;
``simulation`` measures one run; ``records`` holds what a run records, ``figures`` draws
Fig. 1 and Fig. 4. ``oscillation`` (Fig. 4's time-step study) and ``terzaghi`` (the Darcy
solver against Terzaghi's consolidation) are sub-studies, each with its ``*_records``.
"""
