"""Job outputs as plain files: heightmap.csv (x,y,z in mm) and friends.

heightmap.csv: x,y,z first (spreadsheets and other tools read those), then,
for a map that knows them, `source` (how the cell was obtained: seen,
interpolated, extrapolated, occluded, wall, clamped, filled, held) and
`uncertainty_mm` (surface/uncertainty.py). Files with only x,y,z still load.

All writes are atomic (see atomicio). Readers validate and raise
InkSliceError naming the file and the problem.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from . import atomicio
from .errors import InkSliceError
from .surface.heightmap import HeightMap


def heightmap_csv_text(hm: HeightMap) -> str:
    """Rows for every on-part cell, row by row; off-part cells are omitted."""
    from .surface.uncertainty import SOURCES

    X, Y = hm.grid()
    keep = hm.on_part
    pts = np.column_stack([X[keep], Y[keep], hm.z[keep]])
    buf = io.StringIO()
    if hm.sigma is None:
        buf.write("x,y,z\n")
        np.savetxt(buf, pts, fmt="%.4f", delimiter=",")
        return buf.getvalue()
    buf.write("x,y,z,source,uncertainty_mm\n")
    codes = hm.source[keep] if hm.source is not None else np.full(int(keep.sum()), -1)
    names = np.array(list(SOURCES) + ["unknown"])[np.where(codes >= 0, codes, len(SOURCES))]
    u = hm.sigma[keep]
    for (x, y, z), name, ui in zip(pts, names, u):
        buf.write(
            f"{x:.4f},{y:.4f},{z:.4f},{name},{ui:.4f}\n"
            if np.isfinite(ui)
            else f"{x:.4f},{y:.4f},{z:.4f},{name},\n"
        )
    return buf.getvalue()


def write_heightmap_csv(path, hm: HeightMap):
    atomicio.write_text(path, heightmap_csv_text(hm))


# A height map is of a part on a bench box: a lattice beyond these is a broken or hostile
# file, refused with its reason before anything the size of the lattice is allocated.
MAX_HEIGHTMAP_BYTES = 512 * 1024**2
MAX_EXTENT_MM = 2000.0  # x and y span; and |z|
MAX_CELLS = 16_000_000  # a 4000 x 4000 lattice


def read_heightmap_csv(path) -> HeightMap:
    """Rebuild the lattice from the x and y values present (they must form a regular grid)."""
    path = Path(path)
    if not path.is_file():
        raise InkSliceError(path, "height map file does not exist")
    if path.stat().st_size > MAX_HEIGHTMAP_BYTES:
        raise InkSliceError(
            path, f"is {path.stat().st_size} bytes; a height map is at most {MAX_HEIGHTMAP_BYTES}"
        )
    text = path.read_text(encoding="utf-8", errors="replace")
    lines = text.splitlines()
    header = [c.strip().lower() for c in lines[0].split(",")] if lines else []
    if header[:3] != ["x", "y", "z"]:
        raise InkSliceError(path, "first line must be the header 'x,y,z' (further columns may follow)")
    data, extra = _rows(path, lines[1:], header)
    if data.size == 0 or data.shape[1] != 3:
        raise InkSliceError(path, "no x,y,z rows")
    if not np.all(np.isfinite(data)):
        raise InkSliceError(path, "a value is not finite")
    data, extra = _one_height_per_point(path, data, extra)
    span = np.ptp(data, axis=0)
    for k, name in enumerate("xy"):
        if span[k] > MAX_EXTENT_MM:
            raise InkSliceError(
                path,
                f"spans {span[k]:.6g} mm in {name}; a part on the bench is at most "
                f"{MAX_EXTENT_MM:g} mm across",
            )
    if np.max(np.abs(data)) > 1e6 or np.max(np.abs(data[:, 2])) > MAX_EXTENT_MM:
        raise InkSliceError(
            path,
            f"has a coordinate of {np.max(np.abs(data)):.6g} mm, beyond any bench "
            f"(heights at most {MAX_EXTENT_MM:g} mm, positions at most 1e6 mm)",
        )
    xs = np.unique(np.round(data[:, 0], 4))
    ys = np.unique(np.round(data[:, 1], 4))
    for name, v in (("x", xs), ("y", ys)):
        if v.size > 2:
            d = np.diff(v)
            step = np.median(d)
            # gaps of whole steps are allowed (off-part cells), uneven steps are not
            k = d / step
            if np.any(np.abs(k - np.round(k)) > 1e-3):
                raise InkSliceError(path, f"{name} values are not on a regular grid")
    nx, ny = _axis_size(xs), _axis_size(ys)
    if nx * ny > MAX_CELLS:
        raise InkSliceError(
            path,
            f"its rows span a lattice of {nx} x {ny} cells, more than {MAX_CELLS} "
            "(is a row's x or y wrong, or the grid too fine?)",
        )
    x = _regular_axis(xs)
    y = _regular_axis(ys)
    z = np.full((y.size, x.size), np.nan)
    ix = np.rint((data[:, 0] - x[0]) / (x[1] - x[0])).astype(int) if x.size > 1 else np.zeros(len(data), int)
    iy = np.rint((data[:, 1] - y[0]) / (y[1] - y[0])).astype(int) if y.size > 1 else np.zeros(len(data), int)
    z[iy, ix] = data[:, 2]
    sigma = source = None
    if "uncertainty_mm" in extra:
        sigma = np.full(z.shape, np.nan)
        sigma[iy, ix] = extra["uncertainty_mm"]
    if "source" in extra:
        source = np.full(z.shape, -1, np.int8)
        source[iy, ix] = extra["source"]
    return HeightMap(x, y, z, sigma, source)


def _rows(path, rows, header):
    """-> (x,y,z array, {column: values} of the known extra columns: source, uncertainty_mm).
    Other extra columns are read past: another tool may have added its own."""
    from .surface.uncertainty import SOURCES

    if len(header) == 3:
        try:
            return np.loadtxt(io.StringIO("\n".join(rows)), delimiter=",", ndmin=2), {}
        except ValueError as e:
            raise InkSliceError(path, f"not three numbers per line ({str(e)[:120]})") from None
    known = {name: header.index(name) for name in ("source", "uncertainty_mm") if name in header}
    xyz, src, unc = [], [], []
    codes = {name: k for k, name in enumerate(SOURCES)}
    for n, line in enumerate(rows, start=2):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != len(header):
            raise InkSliceError(path, f"line {n} has {len(cells)} values, the header names {len(header)}")
        try:
            xyz.append([float(c) for c in cells[:3]])
        except ValueError:
            raise InkSliceError(path, f"line {n}: x, y and z must be numbers") from None
        if "source" in known:
            name = cells[known["source"]].strip().lower()
            if name not in codes and name not in ("", "unknown"):
                raise InkSliceError(path, f"line {n}: unknown source {name!r}; known: {', '.join(SOURCES)}")
            src.append(codes.get(name, -1))
        if "uncertainty_mm" in known:
            cell = cells[known["uncertainty_mm"]].strip()
            try:
                u = float(cell) if cell else float("nan")
            except ValueError:
                raise InkSliceError(path, f"line {n}: uncertainty_mm must be a number") from None
            if u < 0 or np.isinf(u):
                raise InkSliceError(path, f"line {n}: uncertainty_mm must be a finite number >= 0")
            unc.append(u)
    data = np.array(xyz, float).reshape(-1, 3)
    extra = {}
    if "source" in known:
        extra["source"] = np.array(src, np.int8)
    if "uncertainty_mm" in known:
        extra["uncertainty_mm"] = np.array(unc, float)
    return data, extra


def _one_height_per_point(path, data, extra):
    """Rows repeating an x,y with the same z are dropped; with another z they are an error."""
    xy = np.round(data[:, :2], 4)
    _, first, inverse = np.unique(xy, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if len(first) == len(data):
        return data, extra
    clash = np.abs(data[:, 2] - data[first[inverse], 2]) > 1e-4
    if np.any(clash):
        i = int(np.argmax(clash))
        j = int(first[inverse[i]])
        raise InkSliceError(
            path,
            f"rows {j + 2} and {i + 2} give x={data[i, 0]:g}, y={data[i, 1]:g} two heights "
            f"({data[j, 2]:g} and {data[i, 2]:g} mm)",
        )
    keep = np.sort(first)
    return data[keep], {k: v[keep] for k, v in extra.items()}


def _axis_size(v):
    if v.size < 2:
        return v.size
    return int(round((v[-1] - v[0]) / float(np.min(np.diff(v))))) + 1


def _regular_axis(v):
    if v.size < 2:
        return v
    step = float(np.min(np.diff(v)))
    n = int(round((v[-1] - v[0]) / step)) + 1
    return v[0] + step * np.arange(n)


# -- meniscus.json: the ink's calibrated meniscus (inkslice calibrate --reference) ------------


def meniscus_json(model) -> dict:
    """Only the ink's own parameters: the camera's place comes from each scan's calibration."""
    return {
        "format": "inkslice.meniscus/1",
        "capillary_length_mm": float(model.capillary_length_mm),
        "contact_angle_deg": float(np.degrees(model.contact_angle_rad)),
        "contact_line_curvature": float(model.curvature),
    }


def meniscus_model(doc, camera, where="meniscus"):
    """A MeniscusModel for one scan from a meniscus.json document and the scan's camera."""
    from .surface.meniscus import MeniscusModel

    try:
        lc = float(doc["capillary_length_mm"])
        theta = float(doc["contact_angle_deg"])
        curvature = float(doc.get("contact_line_curvature", 0.0))  # older files: a straight line
    except (KeyError, TypeError, ValueError) as e:
        raise InkSliceError(
            where, f"not a meniscus model (needs capillary_length_mm and contact_angle_deg: {e})"
        ) from None
    if not (0 <= lc <= 20 and -90 <= theta <= 90 and -5 <= curvature <= 5):
        raise InkSliceError(
            where,
            f"impossible meniscus: capillary length {lc} mm, contact angle {theta} deg, "
            f"contact line curvature weight {curvature}",
        )
    return MeniscusModel(lc, float(np.radians(theta)), camera.centre_xy(), camera.height_mm, curvature)
