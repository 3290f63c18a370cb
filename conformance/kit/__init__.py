"""Stage 1, the kit: what an engine is asked to compute, written to and read from files.

``spec`` (models, meshes, states: a case's input), ``cases`` (a kit's cases and probes),
``exchange`` (the file format: JSON manifests and raw arrays, an engine's output),
``confine`` (reading untrusted files: confined, regular, bounded, hashed), ``options`` (the
command-line options that choose the cases).
"""
