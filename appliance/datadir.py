"""Where InkSlice keeps its data (jobs, settings, calibration, the web's files): one rule for the
daemon, the web server and every command.

    1. the --data option, when a command is given one;
    2. else $INKSLICE_DATA (the systemd units set it, tests point it at a temporary folder);
    3. else /var/lib/inkslice when that folder exists: the box, where systemd's StateDirectory
       made it for the inkslice user;
    4. else ~/.local/share/inkslice: a developer's machine or a laptop running the commands.

docs/architecture.md ("Where the data lives") says the same, with what is kept there.
"""

from __future__ import annotations

import os
from pathlib import Path

BOX_DATA = Path("/var/lib/inkslice")
HELP = (
    "data folder (default: $INKSLICE_DATA, else /var/lib/inkslice if it exists, else ~/.local/share/inkslice)"
)


def data_dir(arg: str | os.PathLike | None = None, box: Path = BOX_DATA) -> Path:
    if arg:
        return Path(arg)
    env = os.environ.get("INKSLICE_DATA")
    if env:
        return Path(env)
    if box.is_dir():
        return box
    return Path.home() / ".local" / "share" / "inkslice"
