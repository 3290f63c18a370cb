"""The shear coefficients of a quadratic form in the strain counted with engineering shears.

Costa's Q = E_f . B E_f (E_f the Green strain in the fibre frame, B the symmetric matrix of
b_ff, b_fs, ...) holds each shear pair twice: 2 b_fs E_fs^2. Written in Voigt form with
engineering shear strains e_fs = 2 E_fs, the shear terms must read b_fs e_fs^2 / 2; an engine
that keeps 2 b_fs e_fs^2 has them four times too large (and one that drops the 2 of the pair,
half). The model with the three shear coefficients scaled by one factor is evaluated by the
oracle (:func:`conformance.diagnosis.parameters.with_value`), the factors an engine gets from
these conventions tried in turn.
"""

from __future__ import annotations

from typing import Any, Iterator, Tuple

__all__ = ["SHEAR_COEFFICIENTS", "FACTORS", "shear_variants"]

#: The off-diagonal (shear) coefficients of a model's strain form, by parameter names.
SHEAR_COEFFICIENTS = ("b_fs", "b_fn", "b_sn")

#: factor -> how an engine gets it.
FACTORS = {
    4.0: "the shear terms of Q four times too large: engineering shear strains (e_fs = 2 E_fs) "
    "with the tensor form's 2 b_fs E_fs^2 kept (2 b_fs e_fs^2 for b_fs e_fs^2 / 2), likewise "
    "b_fn and b_sn",
    2.0: "the shear terms of Q doubled (b_fs, b_fn, b_sn counted twice over the off-diagonal "
    "pairs)",
    0.5: "the shear terms of Q halved (each off-diagonal pair b_fs, b_fn, b_sn counted once)",
    0.25: "the shear terms of Q a quarter of their value (engineering shear strains halved)",
}


def shear_variants(model: Any) -> Iterator[Tuple[float, Any, str]]:
    """(factor, the model with its shear coefficients times factor, words) for a model that
    has them, not all zero; nothing for another model.
    """
    from conformance.diagnosis.parameters import with_value

    values = {n: getattr(model, n, None) for n in SHEAR_COEFFICIENTS}
    if any(not isinstance(v, (int, float)) for v in values.values()) or not any(values.values()):
        return
    for factor, words in FACTORS.items():
        try:
            yield factor, with_value(model, **{n: factor * v for n, v in values.items()}), words
        except ValueError:  # outside the model's own bounds
            continue
