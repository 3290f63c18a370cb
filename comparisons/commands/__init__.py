"""The subcommands of mjed-verify, one module each.

A command module defines ``NAME``, ``ORDER`` (its place in ``--help``), ``HELP`` (one line),
``EXAMPLES`` (the epilog), ``configure(parser)`` and ``run(args) -> int``. Modules are found
by name, so adding a subcommand means adding a file here; heavy imports belong inside ``run``
so that ``mjed-verify --help`` stays instant.
"""
