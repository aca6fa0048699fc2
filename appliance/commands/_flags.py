"""The CLI's names for the quantities the pure rooms complain about.

A CAM function raises SettingError("cutter", ...): it knows the quantity, not
how the user gave it. A command that passed a flag's value on says so in its
own terms: `inkslice: error: --rough-cutter: 'ball' is not a cutter name`.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from ..errors import SettingError


@contextmanager
def flags(names: dict[str, str]) -> Iterator[None]:
    """Within the block, a SettingError about a quantity in `names` names its flag instead."""
    try:
        yield
    except SettingError as e:
        if e.where not in names:
            raise
        raise SettingError(names[e.where], e.problem) from None
