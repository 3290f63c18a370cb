"""The simulated rheometer (paper, Fig. 3): ``study`` runs the frequency sweep and judges it,
``records`` holds its input and what it measures.
"""
