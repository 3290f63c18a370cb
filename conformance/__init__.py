"""Check any implementation of hyperelastic forces and stiffness against the oracle, and say what is
wrong.

Three ways in (docs/conventions.md): a kit of files (``mjed-verify export`` / ``mjed-verify check
DIR``),
a command run per case (``mjed-verify check --command 'my_engine {input} {output}'``), and Python:

    from conformance import assert_matches_oracle
    assert_matches_oracle(my_engine, material="NeoHookean", mesh="single-tet")

``my_engine(case)`` receives a :class:`CaseInput` (points, cells, positions, model) and returns
(force (n, 3), stiffness (3n, 3n)[, energy]).
"""

from conformance.diagnosis.diagnose import Diagnosis
from conformance.diagnosis.findings import Finding
from conformance.kit.exchange import (
    FORMAT_VERSION,
    EngineOutput,
    read_case_input,
    read_output,
    write_output,
)
from conformance.kit.spec import CaseInput
from conformance.protocol import Implementation, assert_matches_oracle, check_implementation
from conformance.run import CheckRun

__all__ = [
    "CaseInput",
    "EngineOutput",
    "Implementation",
    "assert_matches_oracle",
    "check_implementation",
    "CheckRun",
    "Diagnosis",
    "Finding",
    "FORMAT_VERSION",
    "read_case_input",
    "read_output",
    "write_output",
]
