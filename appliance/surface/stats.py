"""The dissertation's statistics (eqs 3-27..3-30), computed against ground truth.

    E_i   = |Zf_i - Z_i|                         (Zf original, Z reconstructed)
    max   = max E_i
    Ea    = sum(E_i) / n
    sigma = sqrt(sum((E_i - Ea)^2) / (n - 1))
    Ep as printed (eq 3-30) = sum(|Zf_i - Z_i| / Z_i) * 100 / (n - 1)
    Ep as the tables computed it = 100 * Ea / max|Zf|
    degree of matching = 100 - Ep (table form)

The printed eq 3-30 and the tables disagree: only the second reproduces the
tables (normalisers 32.42, 34.62, 49.81 = each sample's largest |Z| in the
dissertation's frame; 28.36 for sample 4), so both are computed, named apart,
and the table form is used when comparing with the tables. Heights must be
given in the dissertation's frame for Ep to mean what it meant there.
"""

from __future__ import annotations

import numpy as np


def seed_statistics(z_true, z_rec, normaliser=None) -> dict:
    zt = np.asarray(z_true, float).ravel()
    zr = np.asarray(z_rec, float).ravel()
    keep = np.isfinite(zt) & np.isfinite(zr)
    zt, zr = zt[keep], zr[keep]
    n = zt.size
    if n < 2:
        raise ValueError("statistics need at least two cells with both a true and a reconstructed height")
    err = np.abs(zt - zr)
    ea = float(err.mean())
    sigma = float(np.sqrt(np.sum((err - ea) ** 2) / (n - 1)))
    with np.errstate(divide="ignore", invalid="ignore"):
        ep_printed = float(np.sum(err / zr) * 100 / (n - 1)) if np.all(zr != 0) else float("nan")
    norm = float(normaliser) if normaliser is not None else float(np.max(np.abs(zt)))
    ep_table = 100.0 * ea / norm
    return {
        "n": int(n),
        "max_error": float(err.max()),
        "Ea": ea,
        "sigma": sigma,
        "Ep_printed": ep_printed,
        "Ep_table": ep_table,
        "matching": 100.0 - ep_table,
        "normaliser": norm,
    }
