"""The CLI's names for the quantities the pure rooms complain about.

A CAM function raises SettingError("cutter", ...): it knows the quantity, not
how the user gave it. A command that passed a flag's value on says so in its
own terms: `inkslice: error: --rough-cutter: 'ball' is not a cutter name`.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from .. import datadir
from ..errors import SettingError

WEB_PORT = 8080  # the web UI's port, the same for the box and the demo


@contextmanager
def flags(names: dict[str, str]) -> Iterator[None]:
    """Within the block, a SettingError about a quantity in `names` names its flag instead."""
    try:
        yield
    except SettingError as e:
        if e.where not in names:
            raise
        raise SettingError(names[e.where], e.problem) from None


def add_web_address(p, host: str, host_help: str, port_help: str = f"the web UI's port (default {WEB_PORT})"):
    """--host and --port: where the web UI listens."""
    p.add_argument("--host", default=host, help=host_help)
    p.add_argument("--port", type=int, default=WEB_PORT, help=port_help)


def add_daemon_paths(p, data_help: str = datadir.HELP):
    """--data and --socket: the daemon's data folder and its control socket (the web's way in)."""
    p.add_argument("--data", default=None, help=data_help)
    p.add_argument("--socket", default=None, help="the daemon's control socket (default DATA/daemon.sock)")
