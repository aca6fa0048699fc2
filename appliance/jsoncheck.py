"""Checks of values read from a JSON document, each failing as one ScanError that names
the file and the key: scan.json's blocks (scanfile.py, vision/camera_block.py) use them."""

from __future__ import annotations

import math

import numpy as np

from .errors import ScanError


def short(value, n=40) -> str:
    """repr(value), cut to n characters: a hostile value does not flood the error line."""
    text = repr(value)
    return text if len(text) <= n else text[:n] + "..."


def number(where, value, key) -> float:
    """A finite number (not a bool)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScanError(where, f"{key} is not a number: {short(value)}")
    try:
        value = float(value)
    except OverflowError:
        raise ScanError(where, f"{key} is not finite: {short(value)}") from None
    if not math.isfinite(value):
        raise ScanError(where, f"{key} is not finite: {value!r}")
    return value


def positive_up_to(where, value, key, top, why) -> float:
    """A finite number in (0, top]; otherwise `KEY is X: WHY`."""
    x = number(where, value, key)
    if not 0 < x <= top:
        raise ScanError(where, f"{key} is {x:g}: {why}")
    return x


def optional_positive(where, obj, key, label, top, why, default=None):
    """positive_up_to() of obj[key] when it is there and not null, else `default`."""
    if obj.get(key) is None:
        return default
    return positive_up_to(where, obj[key], label, top, why)


def matrix(where, obj, key, shape) -> np.ndarray:
    """A matrix of finite numbers of exactly this shape."""
    try:
        m = np.asarray(obj, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ScanError(where, f"{key} is not a matrix of numbers") from None
    if m.shape != shape:
        raise ScanError(where, f"{key} must be {shape[0]}x{shape[1]}, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ScanError(where, f"{key} has a non-finite entry")
    return m
