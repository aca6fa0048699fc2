"""Small height maps with known shapes for the CAM tests."""

import numpy as np

from appliance.surface.heightmap import HeightMap


def grid_map(f, x0, x1, y0, y1, step):
    nx = int(round((x1 - x0) / step)) + 1
    ny = int(round((y1 - y0) / step)) + 1
    x = np.linspace(x0, x1, nx)
    y = np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(x, y)
    return HeightMap(x, y, np.asarray(f(X, Y), float) + 0 * X)
