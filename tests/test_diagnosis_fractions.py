"""conformance.diagnosis.fractions: fitted factors said as simple fractions only when they are."""

from fractions import Fraction

from conformance.diagnosis.fractions import simple_fraction, written_number


def test_a_fraction_within_the_tolerance_is_found_and_one_outside_is_not():
    assert simple_fraction(-2.0 / 3.0 + 1e-8, 3, 1e-6) == Fraction(-2, 3)
    assert simple_fraction(-2.0 / 3.0 + 1e-4, 3, 1e-6) is None
    # The denominator bounds what counts as simple: 1/5 is not a fraction of denominator <= 4.
    assert simple_fraction(0.2, 4, 1e-6) is None
    assert simple_fraction(0.2, 12, 1e-6) == Fraction(1, 5)


def test_numbers_are_written_as_fractions_or_decimals():
    assert written_number(3.0) == "3"
    assert written_number(-4.0 / 3.0) == "-4/3"
    assert written_number(0.123456, digits=4) == "0.1235"
    # Large numbers are compared relative to their size.
    assert written_number(1e6 / 7.0 * 7.0 + 1e-5) == "1000000"
