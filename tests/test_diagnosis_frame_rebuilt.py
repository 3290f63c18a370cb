"""Only the fibre read from the frame, the sheet and normal rebuilt from a global axis
(conformance.diagnosis.frames, ``frame-rebuilt``): the mistaken engine rebuilds its frame here
the way users write it; the oracle judges.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from common.cases import default_material
from conformance.diagnosis.frames import frame_models
from reference_fem import dolfinx_available


def _from_z(R):
    """The engine's frame: the fibre kept, s = z x f / |z x f|, n = f x s."""
    f = R[..., :, 0]
    s = np.cross([0.0, 0.0, 1.0], f)
    s = s / np.linalg.norm(s, axis=-1, keepdims=True)
    return np.stack([f, s, np.cross(f, s)], axis=-1)


def test_the_rebuilt_frames_are_variants_unless_the_frame_is_already_so_built():
    rng = np.random.default_rng(0)
    R = np.linalg.qr(rng.standard_normal((5, 3, 3)))[0]  # five cells' rotations (orthonormal)
    R = R * np.sign(np.linalg.det(R))[:, None, None]
    model = replace(default_material("Costa"), frame=R)
    rebuilt = {t: m.frame for c, t, m in frame_models(model) if c == "frame-rebuilt"}
    assert any("global z axis" in t for t in rebuilt), list(rebuilt)
    z = next(np.asarray(fr) for t, fr in rebuilt.items() if "global z" in t)
    assert np.allclose(z, _from_z(R))
    # a frame whose sheet already is z x f: its z-rebuilt variant is itself, not a mistake
    same = replace(model, frame=_from_z(R))
    assert not any("global z axis" in t for c, t, _ in frame_models(same) if c == "frame-rebuilt")


@pytest.mark.oracle
@pytest.mark.skipif(not dolfinx_available(), reason="the oracle needs dolfinx")
@pytest.mark.parametrize("mistake", ["rebuilt", "columns"])
def test_a_frame_rebuilt_from_z_is_named_and_swapped_columns_are_not(mistake):
    from frame_support import check_with_frames

    outcome = check_with_frames(
        lambda R, cells: _from_z(R) if mistake == "rebuilt" else R[..., [0, 2, 1]], "fibre-shear"
    )
    d = outcome.diagnosis
    assert outcome.status == "failed" and d.causes, d.text()
    codes = [c.code for c in d.causes]
    if mistake == "rebuilt":
        assert codes == ["frame-rebuilt"] and "global z" in d.causes[0].title, d.text()
    else:
        assert "frame-rebuilt" not in codes, d.text()
