"""Two filled copies of one kit, case by case: how far one engine's outputs are from another's.

Not a verdict (the oracle gives those, ``mjed-verify check``): a direct comparison of two
engines on the same inputs, e.g. MJED's GPU backend against its CPU engine on a machine that
has no oracle.

    python -m conformance.kit.agreement KIT_A KIT_B

prints, per material, the largest difference of force and of stiffness over its cases,
relative to the largest entry of KIT_B's force (stiffness) over the same cases: a case at rest,
whose force is round-off, is measured against the material's force scale, not its own. Exits 1
when the kits do not hold the same cases.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Dict, Optional, Sequence

import numpy as np

from conformance.kit.exchange import read_output
from conformance.kit.read import read_kit

__all__ = ["Agreement", "kit_agreement", "main"]

_TINY = 1e-300  # a material whose reference outputs are all zero: the differences as they are


@dataclass(frozen=True)
class Agreement:
    """The largest relative differences of one material's cases (force, stiffness), and how
    many cases were compared.
    """

    model: str
    force: float
    stiffness: float
    cases: int


def kit_agreement(kit_a: str, kit_b: str) -> Dict[str, Agreement]:
    """Per material (the first part of a case id), the largest difference of force and of
    stiffness of ``kit_a``'s outputs from ``kit_b``'s, relative to the largest entry of
    ``kit_b``'s force (stiffness) over that material's cases.

    Raises:
        ValueError: the kits do not hold the same cases (ids), naming the first difference.
        FormatError: an output is missing or malformed (from the kit reader).
    """
    a, b = read_kit(kit_a), read_kit(kit_b)
    ids_a, ids_b = [c.case_id for c in a.cases], [c.case_id for c in b.cases]
    if ids_a != ids_b:
        only = sorted(set(ids_a) ^ set(ids_b)) or ["(same ids, another order)"]
        raise ValueError(f"{kit_a} and {kit_b} hold different cases: first {only[0]}")
    # per material: [largest force difference, largest force, same for stiffness, cases]
    sums: Dict[str, list] = {}
    for ca, cb in zip(a.cases, b.cases):
        n = ca.input.n_nodes
        oa = read_output(ca.output_dir, n, ca.case_id)
        ob = read_output(cb.output_dir, n, cb.case_id)
        s = sums.setdefault(ca.case_id.split(".")[0], [0.0, 0.0, 0.0, 0.0, 0])
        s[0] = max(s[0], float(np.abs(oa.force - ob.force).max()))
        s[1] = max(s[1], float(np.abs(ob.force).max()))
        s[2] = max(s[2], float(abs(oa.stiffness - ob.stiffness).max()))
        s[3] = max(s[3], float(abs(ob.stiffness).max()))
        s[4] += 1
    return {
        model: Agreement(model, df / max(f, _TINY), dK / max(K, _TINY), n)
        for model, (df, f, dK, K, n) in sums.items()
    }


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m conformance.kit.agreement", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("kit_a", help="a filled kit")
    ap.add_argument("kit_b", help="the same kit filled by another engine (the reference)")
    args = ap.parse_args(argv)
    try:
        worst = kit_agreement(args.kit_a, args.kit_b)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    precision = read_kit(args.kit_a).precision
    for w in worst.values():
        print(
            f"  {w.model:20s} ({precision}, {w.cases} cases) against {args.kit_b}: "
            f"force {w.force:.1e}, stiffness {w.stiffness:.1e}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
