"""The compressed-element regularisation study (paper, section 2.3): ``study``."""
