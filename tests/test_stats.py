"""The dissertation's statistics (eqs 3-27..3-30) on hand-computed cases."""

import math

import numpy as np
import pytest

from appliance.surface.stats import seed_statistics


def test_hand_computed_case():
    zt = np.array([10.0, 20.0, 30.0, 40.0])
    zr = np.array([11.0, 18.0, 30.0, 44.0])  # errors 1, 2, 0, 4
    s = seed_statistics(zt, zr)
    assert s["n"] == 4
    assert s["max_error"] == 4.0
    assert s["Ea"] == pytest.approx(7 / 4)
    # sigma with n - 1: deviations -0.75, 0.25, -1.75, 2.25
    assert s["sigma"] == pytest.approx(math.sqrt((0.5625 + 0.0625 + 3.0625 + 5.0625) / 3))
    # as printed: sum(|Zf - Z| / Z) * 100 / (n - 1)
    assert s["Ep_printed"] == pytest.approx((1 / 11 + 2 / 18 + 0 / 30 + 4 / 44) * 100 / 3)
    # as the tables computed it: 100 * Ea / max|Zf|
    assert s["Ep_table"] == pytest.approx(100 * 1.75 / 40)
    assert s["matching"] == pytest.approx(100 - 100 * 1.75 / 40)


@pytest.mark.parametrize(
    "ea, normaliser, ep_table, matching",
    [
        (0.5319, 49.81, 1.0678, 98.9322),  # table 5-3, least squares
        (2.4648, 28.36, 8.6913, 91.3087),  # table 5-4, least squares
        (0.6573, 32.42, 2.0273, 97.9727),  # table 5-1, least squares
        (3.7843, 34.62, 10.9313, 89.0687),  # table 5-2, as captured
    ],
)
def test_table_normalisation_reproduces_the_tables(ea, normaliser, ep_table, matching):
    """The tables divide Ea by the sample's largest |Z|; matching is 100 - that."""
    zt = np.array([normaliser, -normaliser / 2, 1.0])
    s = seed_statistics(zt, zt + ea, normaliser=normaliser)
    assert s["Ep_table"] == pytest.approx(ep_table, abs=5e-4)  # the tables divided by unrounded Ea and max|Z|
    assert s["matching"] == pytest.approx(100 - s["Ep_table"], abs=1e-12)
    assert round(100 - ep_table, 4) == matching


def test_matching_from_the_printed_percentage():
    """Table 5-3's check (docs/method.md): 1.0678 % error is 98.9322 % matching."""
    zt = np.array([49.81, 10.0])
    s = seed_statistics(zt, zt + 1.0678 * 49.81 / 100, normaliser=49.81)
    assert round(s["matching"], 4) == 98.9322


def test_cells_without_data_are_left_out():
    zt = np.array([1.0, np.nan, 3.0])
    zr = np.array([1.5, 2.0, np.nan])
    with pytest.raises(ValueError):
        seed_statistics(zt, zr)
    s = seed_statistics(np.array([1.0, 2.0, np.nan]), np.array([1.5, 2.5, 9.0]))
    assert s["n"] == 2 and s["Ea"] == pytest.approx(0.5)


def test_zero_error_gives_full_matching():
    z = np.linspace(-30, -1, 50)
    s = seed_statistics(z, z)
    assert s["Ea"] == 0 and s["sigma"] == 0 and s["matching"] == 100.0
