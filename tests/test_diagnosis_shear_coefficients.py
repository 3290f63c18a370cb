"""Costa's shear coefficients scaled by one factor (conformance.diagnosis.shear_coefficients,
read in conformance.diagnosis.readings): the engine built here is MJED's Costa with b_fs,
b_fn, b_sn four times their values (Q's shear terms with engineering shear strains).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from conftest import box_mesh
from diagnosis_stubs import CaseStub as _Case
from diagnosis_stubs import MjedCache as _Cache
from diagnosis_stubs import OutputStub as _Out

from common.cases import default_material
from conformance.diagnosis.readings import _shear_readings
from conformance.diagnosis.shear_coefficients import shear_variants
from conformance.judge.compare import DOUBLE, scales


def test_shear_variants_scale_the_three_shear_coefficients_only():
    model = default_material("Costa")
    found = {f: v for f, v, _ in shear_variants(model)}
    assert set(found) == {4.0, 2.0, 0.5, 0.25}
    v = found[4.0]
    assert (v.b_fs, v.b_fn, v.b_sn) == (4 * model.b_fs, 4 * model.b_fn, 4 * model.b_sn)
    assert (v.b_ff, v.b_ss, v.b_nn) == (model.b_ff, model.b_ss, model.b_nn)
    assert list(shear_variants(default_material("NeoHookean"))) == []


def test_shear_terms_four_times_are_named_and_three_times_are_not():
    model = default_material("Costa")
    points, cells = box_mesh(2, jitter=0.2, seed=4)
    x = points + 0.05 * np.random.default_rng(1).standard_normal(points.shape)
    ci = _Case(points, cells, x, model)
    ref = _Cache().evaluate_once(ci, model)
    s = scales(0.5, 1.0, ref.force, ref.stiffness)
    for factor, named in ((4.0, True), (3.0, False)):
        scaled = replace(
            model, b_fs=factor * model.b_fs, b_fn=factor * model.b_fn, b_sn=factor * model.b_sn
        )
        r = _Cache().evaluate_once(ci, scaled)
        found = _shear_readings(_Cache(), ci, _Out(r.force, r.stiffness), s, DOUBLE)
        assert [f.finding.figures["factor"] for f in found] == ([4.0] if named else [])
        if named:
            assert "engineering shear" in found[0].finding.title
