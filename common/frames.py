"""Fibre frames for anisotropic cases: a cardiac-like field that turns from cell to cell.

A frame R (3, 3) holds, as its columns, the fibre, sheet and normal directions in global
coordinates: it maps material (fibre-frame) components to global ones, v_global = R v_frame,
and the strain in the frame is R^T E R (docs/conventions.md, "Fibre frames").

The default field of a mesh (:func:`helix_frames`) imitates the fibre architecture of a
ventricular wall: one axis of the mesh (x by default) plays the transmural direction, and the
helix angle of the fibre turns linearly from -60 deg on one face of the mesh to +60 deg on the
other. Two constant angles take every cell's frame away from the global axes and from any
relabelling of them: the fibre leaves the wall plane by a transverse angle, and the sheet and
normal turn about the fibre by a sheet angle. Without them the mid-wall frame would be a signed
permutation of the identity, which an engine that swaps or ignores axes could still match.

Everything here is a pure function of arrays; no mesh object is needed.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, replace
from typing import Any, Tuple

import numpy as np

__all__ = [
    "HelixField",
    "HELIX",
    "helix_frames",
    "signed_permutations",
    "permutation_distance",
    "mid_wall_frame",
    "needs_frame",
    "with_default_frame",
]


@dataclass(frozen=True)
class HelixField:
    """The parameters of a helical fibre field (angles in degrees).

    axis: the mesh axis across which the helix angle turns (0, 1 or 2: the transmural axis).
    helix: the helix angle at the low and at the high end of that axis, linear in between.
    transverse: the fibre's tilt out of the wall plane, towards the transmural axis.
    sheet: the rotation of sheet and normal about the fibre.
    """

    axis: int = 0
    helix: Tuple[float, float] = (-60.0, 60.0)
    transverse: float = 20.0
    sheet: float = 30.0

    def __post_init__(self) -> None:
        if self.axis not in (0, 1, 2):
            raise ValueError(f"HelixField: axis must be 0, 1 or 2, got {self.axis!r}")
        if len(self.helix) != 2 or not np.all(np.isfinite(self.helix)):
            raise ValueError(f"HelixField: helix must be two finite angles, got {self.helix!r}")
        if not (np.isfinite(self.transverse) and np.isfinite(self.sheet)):
            raise ValueError("HelixField: transverse and sheet angles must be finite")


#: The field every kit and the equivalence study give a material that needs a frame.
HELIX = HelixField()


def _rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotations (k, 3, 3) by ``angle`` (k,) [rad] about global axis ``axis`` (right-handed)."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    R = np.zeros(angle.shape + (3, 3))
    R[..., axis, axis] = 1.0
    R[..., i, i], R[..., i, j], R[..., j, i], R[..., j, j] = c, -s, s, c
    return R


def _frames_at(t: np.ndarray, field: HelixField) -> np.ndarray:
    """Frames (k, 3, 3) at wall depths t (k,) in [0, 1]."""
    a = field.axis
    # Transmural, circumferential, longitudinal: a cyclic relabelling, so a proper rotation.
    trans, circ, longi = a, (a + 1) % 3, (a + 2) % 3
    base = np.zeros((3, 3))
    base[circ, 0] = 1.0  # fibre along the circumferential axis before any rotation
    base[trans, 1] = 1.0  # sheet along the transmural axis
    base[longi, 2] = -1.0  # normal = fibre x sheet
    lo, hi = np.deg2rad(field.helix)
    helix = lo + (hi - lo) * np.asarray(t, dtype=np.float64)
    tilt = _rotation(longi, np.array(np.deg2rad(field.transverse)))  # fibre out of the wall plane
    sheet = _rotation(0, np.array(np.deg2rad(field.sheet)))  # about the frame's own fibre
    # R = Rot_r(helix) Rot_l(transverse) base Rot_f(sheet): a product of rotations, so orthonormal
    # and right-handed in every cell.
    return _rotation(trans, helix) @ (tilt @ base @ sheet)


def helix_frames(points: np.ndarray, cells: np.ndarray, field: HelixField = HELIX) -> np.ndarray:
    """One frame per cell (m, 3, 3), columns fibre, sheet, normal, for the helical field.

    points: (n, 3) rest positions [m]; cells: (m, 4) node indices. The wall depth of a cell is
    its centroid's coordinate along ``field.axis``, scaled to [0, 1] over the points' extent
    (a mesh flat along that axis gets the mid-wall frame everywhere).
    """
    X = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells, dtype=np.int64)
    z = X[cells].mean(axis=1)[:, field.axis]
    lo, hi = X[:, field.axis].min(), X[:, field.axis].max()
    t = (z - lo) / (hi - lo) if hi > lo else np.full(z.shape, 0.5)
    return _frames_at(t, field)


def mid_wall_frame(field: HelixField = HELIX) -> np.ndarray:
    """The frame (3, 3) at mid-wall depth (t = 1/2; helix angle 0 for the default field)."""
    return _frames_at(np.array([0.5]), field)[0]


def signed_permutations() -> np.ndarray:
    """The 48 signed permutation matrices (48, 3, 3): the global axes relabelled and flipped."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            P = np.zeros((3, 3))
            P[list(perm), range(3)] = signs
            out.append(P)
    return np.array(out)


def permutation_distance(R: np.ndarray) -> np.ndarray:
    """(m,) the Frobenius distance of each frame of R (m, 3, 3) to the nearest signed permutation
    of the global axes (0 for the identity or an axis relabelling; at most about 1.5).
    """
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    d = np.linalg.norm(R[:, None] - signed_permutations()[None], axis=(2, 3))
    return d.min(axis=1)


def needs_frame(model: Any) -> bool:
    """True for a model whose energy depends on material directions and that has none yet: a
    Costa material without a frame, or a user energy using I4/I5 with neither a fibre nor a
    frame (:attr:`reference_fem.user_energy.UserEnergy.direction_missing`).
    """
    from mjed.materials import Costa

    if isinstance(model, Costa):
        return model.frame is None
    return bool(getattr(model, "direction_missing", False))


def with_default_frame(
    model: Any, points: np.ndarray, cells: np.ndarray, field: HelixField = HELIX
) -> Any:
    """``model`` with the helical field of this mesh (:func:`helix_frames`) when it needs a frame
    and has none (:func:`needs_frame`); any other model, or one given a frame, is returned as is.
    """
    if not needs_frame(model):
        return model
    from reference_fem.user_energy import PrestressWarning

    with warnings.catch_warnings():
        # A pre-stressed user energy was reported when it was built; its copy would say it again.
        warnings.simplefilter("ignore", PrestressWarning)
        return replace(model, frame=helix_frames(points, cells, field))
