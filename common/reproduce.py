"""Spell the command line that re-runs a study exactly as it ran.

Every :class:`common.result.StudyResult` carries a ``command``. It is built here from the
arguments the study actually received (not from the defaults of a parser), so that ``--quick``,
a ``--mesh PATH``, a ``--material`` subset or ``--only`` are never lost. The inverse direction
(parsing the line back with the CLI parser) is what the tests check.

    >>> command("equivalence", material="NeoHookean,Ogden", mesh="single-tet", states="all")
    'mjed-verify equivalence --material NeoHookean,Ogden --mesh single-tet --states all'
"""

from __future__ import annotations

import shlex
from typing import Iterable, Optional, Sequence, Union

__all__ = ["PROGRAM", "command", "material_option", "mesh_option", "states_option", "only_option"]

PROGRAM = "mjed-verify"

Value = Union[str, int, float, bool, None]


def command(
    subcommand: str, *, prefix: Sequence[str] = (), comment: str = "", **options: Value
) -> str:
    """``mjed-verify SUBCOMMAND --opt value ...`` with shell quoting.

    Args:
        subcommand: the subcommand (words separated by spaces).
        prefix: words before the program (e.g. ``("mpirun", "-n", "2")``).
        comment: appended as a shell comment (``# ...``) when something cannot be spelled as an
            option (a material with parameters the command line cannot set).
        **options: keyword ``snake_case`` becomes ``--kebab-case``; True gives a bare flag; None
            and False are left out (they are the parser's defaults); other values are quoted.
    """
    words = [*prefix, PROGRAM, *subcommand.split()]
    for key, value in options.items():
        if value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        words.append(flag) if value is True else words.extend((flag, str(value)))
    line = " ".join(shlex.quote(w) for w in words)
    return f"{line}  # {comment}" if comment else line


def material_option(materials: Iterable) -> tuple:
    """(--material value, comment): 'all' for the full default set, else the names in order.

    The command line selects the default parameter sets of :mod:`common.cases` by name;
    a material whose parameters differ from its default is named in the comment, since no
    option reproduces it.
    """
    from common.cases import DEFAULT_MATERIALS

    materials = list(materials)
    names = [m.name for m in materials]
    custom = [m.name for m in materials if DEFAULT_MATERIALS.get(m.name) != m]
    comment = (
        f"custom parameters for {', '.join(custom)}: the command line uses those of common/cases.py"
        if custom
        else ""
    )
    if not custom and names == list(DEFAULT_MATERIALS):
        return "all", comment
    return ",".join(names), comment


def mesh_option(labels: Iterable[str]) -> str:
    """The --mesh value: 'all' for the default built-in set, else the labels (names or paths as
    given).
    """
    from common.options import DEFAULT_MESHES

    labels = list(labels)
    return "all" if tuple(labels) == DEFAULT_MESHES else ",".join(labels)


def states_option(states: Iterable[str]) -> str:
    """The --states value: 'all' for every state in order, else the names."""
    from common.states import state_names

    states = list(states)
    return "all" if states == list(state_names()) else ",".join(states)


def only_option(keys: Optional[Iterable[str]]) -> Optional[str]:
    return None if keys is None else ",".join(keys)
