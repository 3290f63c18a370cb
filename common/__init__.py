"""The layer both applications stand on: results, verdicts, tolerances, states, cases, options
and rendering.

``comparisons`` (the studies and the command line) and ``conformance`` (checking other engines
against the oracle) both judge, report and take options the same way; what they share lives
here, and this package imports neither of them (tests/test_architecture.py holds the layers).

Modules: ``result`` (statuses, checks, study results, exit codes), ``verdict`` (what a result
means for the user), ``tolerances`` (what "agrees with the oracle" means), ``states``
(deformation states), ``cases`` (materials by name), ``options`` (command-line options and
bad-input errors), ``blocks`` and ``render`` (report content and its HTML/Markdown form),
``terminal`` and ``progress`` (what the terminal shows), ``reproduce`` (the command line that
reproduces a result).
"""
