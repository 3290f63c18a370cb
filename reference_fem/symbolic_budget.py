"""A budget on the symbolic work of a user energy: time and memory, with a clear message.

The parser bounds what a user energy may *say* (reference_fem.user_energy), not what UFL and
FFCx spend differentiating and compiling it: a product of forty components of C, 166
characters, costs FFCx about 50 s and 600 MB for one tetrahedron, and twice that length far
more. That work is pure Python and C compilation, which cannot be interrupted safely inside this
process, so it is done first in a child process, under a time limit and an address-space
limit (``RLIMIT_AS``). The forms it compiles land in FFCx's cache, which is keyed by the form's
signature (not the mesh), so the oracle built next in this process finds them there. A child
past its budget is killed and the energy is refused, naming the budget.

Run as a module it is that child: ``python -m reference_fem.symbolic_budget`` reads the
energy as JSON on stdin and builds the oracle on one tetrahedron.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from typing import Any, Optional, Set

import numpy as np

__all__ = ["SymbolicBudgetError", "SYMBOLIC_SECONDS", "SYMBOLIC_BYTES", "check_symbolic_budget"]

SYMBOLIC_SECONDS = 60.0  # the built-in energies compile in 3 to 10 s on the 2-core machine
SYMBOLIC_BYTES = 2 << 30  # address space: dolfinx with PETSc and MPI maps about 0.7 GB at start

_within: Set[str] = set()  # the forms of energies already shown to fit (this process, _form_key)


class SymbolicBudgetError(ValueError):
    """The symbolic work of a user energy exceeded its time or memory budget."""


def _key(energy: Any) -> str:
    """The energy as JSON for the child. A frame is reduced to what shapes the forms (one
    global frame, or one per cell: the child's single cell gets the first), since FFCx's cache
    key is the form, not the mesh or the values.
    """
    frame = getattr(energy, "frame", None)
    if frame is not None:
        frame = np.asarray(frame, dtype=float)
        frame = frame.tolist() if frame.ndim == 2 else frame[:1].tolist()
    return json.dumps(
        {
            "expression": energy.expression,
            "params": dict(energy.params),
            "fibre": None if energy.fibre is None else list(energy.fibre),
            "frame": frame,
            "name": energy.name,
        },
        sort_keys=True,
    )


def _form_key(energy: Any) -> str:
    """What shapes the compiled forms of ``energy``, and nothing else: its expression, the names
    of its parameters (their values enter the forms as Constants), and its fibre direction as
    the oracle writes it into the form (a fibre or one frame for the mesh: its numbers; a frame
    per cell: only that there is one, read from a DG0 Function). Energies with one form key
    have the same symbolic work: the diagnosis' frame variants of one user energy (columns
    exchanged, transposed, one per block of cells, ...) are checked once, not once each.
    """
    frame = getattr(energy, "frame", None)
    if frame is not None:
        frame = np.asarray(frame, dtype=float)
        frame = frame[:, 0].tolist() if frame.ndim == 2 else "one per cell"
    return json.dumps(
        {
            "expression": energy.expression,
            "params": sorted(energy.params),
            "fibre": None if energy.fibre is None else list(energy.fibre),
            "frame": frame,
        },
        sort_keys=True,
    )


def _limit_memory(nbytes: int) -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (nbytes, nbytes))


def check_symbolic_budget(
    energy: Any, *, seconds: Optional[float] = None, nbytes: Optional[int] = None
) -> None:
    """Compile ``energy``'s oracle forms in a child within the budget, or raise
    SymbolicBudgetError saying which limit it exceeded. A no-op for an energy whose forms
    (:func:`_form_key`) fitted before.
    """
    seconds = SYMBOLIC_SECONDS if seconds is None else seconds
    nbytes = SYMBOLIC_BYTES if nbytes is None else nbytes
    form = _form_key(energy)
    if form in _within:
        return
    key = _key(energy)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen(
        [sys.executable, "-m", "reference_fem.symbolic_budget"],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
        preexec_fn=lambda: _limit_memory(nbytes),
        start_new_session=True,
    )
    shown = f"{energy.expression[:80]!r}{'...' if len(energy.expression) > 80 else ''}"
    try:
        _, err = proc.communicate(key.encode(), timeout=seconds)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the child and the compiler it may have started
        proc.communicate()
        raise SymbolicBudgetError(
            f"user energy {shown}: differentiating and compiling it took more than {seconds:g} s "
            "(the symbolic budget); simplify the expression (long products of components of C or E "
            "are the usual cause)"
        ) from None
    if proc.returncode != 0:
        text = err.decode("utf-8", "replace")
        signs = ("MemoryError", "Cannot allocate memory", "bad_alloc", "out of memory")
        memory = proc.returncode < 0 or any(w in text for w in signs)
        last = (text.strip().splitlines() or ["no message"])[-1][:200]
        why = (
            f"needed more than {nbytes >> 20} MiB of address space (the symbolic budget)"
            if memory
            else f"failed ({last})"
        )
        raise SymbolicBudgetError(
            f"user energy {shown}: differentiating and compiling it {why}; simplify the expression"
        )
    _within.add(form)


def _child() -> int:
    import logging

    from reference_fem import UFLOracle
    from reference_fem.user_energy import UserEnergy

    logging.disable(logging.INFO)
    data = json.loads(sys.stdin.read())
    fibre = None if data["fibre"] is None else tuple(data["fibre"])
    frame = None if data["frame"] is None else np.array(data["frame"])
    energy = UserEnergy(
        expression=data["expression"],
        params=data["params"],
        fibre=fibre,
        frame=frame,
        name=data["name"],
    )
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    UFLOracle(points, np.array([[0, 1, 2, 3]]), energy).compile_forms()  # all three, in budget
    return 0


if __name__ == "__main__":
    sys.exit(_child())
