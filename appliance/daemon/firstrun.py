"""The first-run password's way from the web server to the bench's display.

The web server makes the admin password (web/auth.py) but has no devices;
the daemon has the display but no say in the web's login. On the box they are
two systemd units running as the same user over the same data folder
(/var/lib/inkslice), so the hand-over is a file there:

    DATA/first-run-password     mode 0600, the password and a newline

The web writes it when it generates a password (first run, or `--new-password`)
and deletes it at the first successful login or password change; the daemon
shows it on the display while it exists and no scan or notice needs the
screen. A file rather than a call over the daemon's socket: either service
may start, restart or crash first, and the password must still reach the
screen until somebody has logged in. The plain text lives only as long as
nobody has logged in, readable only by the inkslice user, and is the same
secret the display shows to anyone standing at the bench.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..atomicio import write_bytes

FILE = "first-run-password"
MAX_LEN = 64


def hand_over(folder, password: str) -> Path:
    """Leave the password for the daemon's display (0600, written atomically)."""
    path = Path(folder) / FILE
    write_bytes(path, (password + "\n").encode())
    os.chmod(path, 0o600)  # mkstemp made it 0600 already; say so for the reader
    return path


def done(folder) -> bool:
    """Somebody has logged in: the display stops showing it. True if there was one."""
    try:
        (Path(folder) / FILE).unlink()
        return True
    except FileNotFoundError:
        return False


class Pending:
    """The daemon's side: pending() is the password while the file exists, else None.

    Called from the panel loop several times a second, so it only stats the file
    and re-reads it when it changed.
    """

    def __init__(self, folder):
        self.path = Path(folder) / FILE
        self._key = None
        self._value = None

    def pending(self) -> str | None:
        try:
            st = self.path.stat()
        except OSError:
            self._key = self._value = None
            return None
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        if key != self._key:
            try:
                text = self.path.read_text(errors="replace").strip()
            except OSError:
                return None
            self._key, self._value = key, (text[:MAX_LEN] or None)
        return self._value
