"""The error and uncertainty pictures: the part keeps its proportions, the title fits, the colour
scale says its unit, and no two labels are drawn over each other."""

import numpy as np
import pytest

from appliance import plots

TITLES = [
    "short",
    "sample3: InkSlice regularised fit (our waterlines), error against the true part of 2013",
    "x" * 12 + " " + "y" * 40,
]


@pytest.mark.parametrize("span", [(100, 100), (100, 50), (10, 100), (150, 12), (3, 3)])
@pytest.mark.parametrize("title", TITLES)
def test_labels_never_overlap_and_the_map_keeps_the_part_proportions(span, title):
    x = np.linspace(0, span[0], 40)
    y = np.linspace(-5, -5 + span[1], 30)
    err = np.abs(np.random.default_rng(1).normal(0, 0.1, (30, 40)))
    canvas, to_px, boxes = plots._field_picture(err, x, y, title, None, "error, mm", 480)
    assert plots.overlaps(boxes) == []
    h, w = canvas.shape[:2]
    assert all(0 <= b[0] and b[2] <= w and 0 <= b[1] and b[3] <= h for b in boxes), "a label off the picture"
    (x0, y1), (x1, y0) = to_px(x[0], y[-1]), to_px(x[-1], y[0])
    drawn = (x1 - x0 + 1) / (y0 - y1 + 1)
    assert drawn == pytest.approx(span[0] / span[1], rel=0.05) or min(x1 - x0, y0 - y1) + 1 == 40


def test_the_colour_scale_has_its_unit_and_the_overlap_check_catches_a_collision():
    x = y = np.linspace(0, 50, 20)
    canvas, _, boxes = plots._field_picture(np.ones((20, 20)), x, y, "t", 0.3, "error, mm", 300)
    assert any(b[2] - b[0] == plots._Labels.size("error, mm", 0.45)[0] for b in boxes)
    assert plots.overlaps([(0, 0, 10, 10), (5, 5, 20, 20)]) and not plots.overlaps(
        [(0, 0, 10, 10), (10, 0, 20, 10)]
    )


def test_error_map_and_uncertainty_map_still_make_pngs():
    x = y = np.linspace(0, 30, 15)
    png = plots.error_map(np.full((15, 15), 0.02), x, y, "flat")
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
