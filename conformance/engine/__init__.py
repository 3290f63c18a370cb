"""Stage 2, the engine: running someone else's engine on a case.

``command`` runs a command line per case, ``process`` runs one untrusted process bounded in
time and output and ends its whole process tree. Adapters for other libraries are in
``conformance.adapters``.
"""
