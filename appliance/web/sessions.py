"""Server-side login sessions: the cookie names a session, this table says whether it still exists.

Flask's signed cookie alone cannot be taken back: a copied cookie would keep
working until it expires, logout or not. So every login opens a row here
(a random 256-bit id, kept in the signed cookie) and every request checks it;
logout deletes the row, a password change deletes every row but the
changer's. DATA/web/sessions.sqlite, mode 0600.
"""

from __future__ import annotations

import os
import secrets
import sqlite3
import threading
import time
from pathlib import Path


class SessionStore:
    def __init__(self, path, lifetime_s: float, clock=time.time):
        self.path = Path(path)
        self.lifetime_s, self.clock = float(lifetime_s), clock
        self._lock = threading.Lock()
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None, timeout=5)
        os.chmod(self.path, 0o600)
        self._db.execute("CREATE TABLE IF NOT EXISTS sessions (id TEXT PRIMARY KEY, created REAL NOT NULL)")

    def open(self) -> str:
        sid = secrets.token_urlsafe(32)
        now = self.clock()
        with self._lock:
            self._db.execute("DELETE FROM sessions WHERE created < ?", (now - self.lifetime_s,))
            self._db.execute("INSERT INTO sessions (id, created) VALUES (?, ?)", (sid, now))
        return sid

    def valid(self, sid) -> bool:
        if not isinstance(sid, str) or not sid:
            return False
        with self._lock:
            row = self._db.execute("SELECT created FROM sessions WHERE id = ?", (sid,)).fetchone()
        return row is not None and row[0] + self.lifetime_s > self.clock()

    def revoke(self, sid) -> None:
        if isinstance(sid, str):
            with self._lock:
                self._db.execute("DELETE FROM sessions WHERE id = ?", (sid,))

    def revoke_all(self, keep: str | None = None) -> None:
        with self._lock:
            self._db.execute("DELETE FROM sessions WHERE id IS NOT ?", (keep,))

    def count(self) -> int:
        with self._lock:
            return self._db.execute("SELECT COUNT(*) FROM sessions").fetchone()[0]

    def close(self):
        with self._lock:
            self._db.close()
