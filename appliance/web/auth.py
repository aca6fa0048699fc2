"""Who may use the bench: the admin password, sessions, CSRF, API tokens, login rate limit.

Access control is on by default and cannot be switched off: the box sits on a
LAN with phones, guests and IoT gadgets, and the complaints about OctoPrint and
friends were about exactly that (anonymous control, an open webcam stream).

- First run: no password exists, so one is generated (12 random characters),
  its scrypt hash is stored in DATA/web/admin.json with mode 0600 and the
  plain text is handed back once to whoever started the server (printed by
  `inkslice serve` / the demo, and left in DATA/first-run-password (0600) for
  the daemon to show on the bench's display until the first login, see
  daemon/firstrun.py). The UI asks to change it after the first login.
- Sessions are Flask's signed cookies (key in DATA/web/secret_key, 0600),
  HttpOnly and SameSite=Strict always, Secure when the box is served over
  HTTPS (config "https"; a LAN box rarely has a certificate, and a Secure
  cookie over plain HTTP would simply never come back). A session carries the
  password "generation": changing the password bumps it and so logs every
  other session out, which a signed cookie alone cannot do.
- CSRF: every state-changing request (anything but GET/HEAD/OPTIONS) made with
  a session must carry the session's token in the X-CSRF-Token header or a
  csrf_token form field. SameSite=Strict already stops most cross-site posts;
  the token covers older browsers and same-site attackers (another service on
  the same host name).
- API tokens for scripts: `Authorization: Bearer isk_...`. Only their SHA-256
  is stored (they are 256-bit random, so a slow hash buys nothing). A bearer
  header is never sent by a browser on its own, so token requests need no
  CSRF token.
- Login rate limit: per client address, at most N failures in a sliding
  window; past that every attempt (even a right one) gets 429 until the window
  has moved on. scrypt's cost (~50 ms) slows guessing further.
"""
from __future__ import annotations

import hashlib
import hmac
import json
import os
import secrets
import threading
import time
from collections import defaultdict, deque
from pathlib import Path

from werkzeug.security import check_password_hash, generate_password_hash

from ..atomicio import write_bytes, write_json

MIN_PASSWORD = 8
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


def _private_write_json(path: Path, obj):
    write_json(path, obj)
    os.chmod(path, 0o600)       # mkstemp already makes 0600; say it explicitly for the reader


class Credentials:
    """The admin password and the API tokens, kept in DATA/web/ with mode 0600."""

    def __init__(self, folder):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        os.chmod(self.folder, 0o700)
        self.admin_file = self.folder / "admin.json"
        self.tokens_file = self.folder / "tokens.json"
        self._lock = threading.Lock()
        self._files: dict[Path, tuple] = {}

    # -- the password -----------------------------------------------------------
    def ensure_admin(self) -> str | None:
        """Create the first-run password if none exists; returns it (once) or None."""
        with self._lock:
            if self.admin_file.exists():
                return None
            password = "-".join(secrets.token_urlsafe(12)[i:i + 4] for i in (0, 4, 8))
            _private_write_json(self.admin_file, {"hash": generate_password_hash(password, "scrypt"),
                                                  "generation": 1, "must_change": True,
                                                  "set": time.time()})
            return password

    def reset_generated(self) -> str:
        """A fresh generated password (the demo prints one every start); old sessions end."""
        with self._lock:
            old = self._read_json(self.admin_file, None) or {"generation": 0}
            password = "-".join(secrets.token_urlsafe(12)[i:i + 4] for i in (0, 4, 8))
            _private_write_json(self.admin_file, {"hash": generate_password_hash(password, "scrypt"),
                                                  "generation": int(old["generation"]) + 1,
                                                  "must_change": True, "set": time.time()})
            return password

    def _read_json(self, path: Path, default):
        """Parsed file contents, re-read only when the file changes (every request checks the
        password generation; a stat is far cheaper than reading and parsing JSON)."""
        try:
            st = path.stat()
        except FileNotFoundError:
            return default
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        hit = self._files.get(path)
        if hit is None or hit[0] != key:
            hit = (key, json.loads(path.read_text()))
            self._files[path] = hit
        return hit[1]

    def _admin(self) -> dict:
        return dict(self._read_json(self.admin_file, None))

    def generation(self) -> int:
        return int(self._admin()["generation"])

    def must_change(self) -> bool:
        return bool(self._admin().get("must_change"))

    def check_password(self, password: str) -> bool:
        return isinstance(password, str) and check_password_hash(self._admin()["hash"], password)

    def set_password(self, new: str) -> int:
        if not isinstance(new, str) or len(new) < MIN_PASSWORD:
            raise ValueError(f"the password needs at least {MIN_PASSWORD} characters")
        with self._lock:
            doc = self._admin()
            doc.update(hash=generate_password_hash(new, "scrypt"), generation=int(doc["generation"]) + 1,
                       must_change=False, set=time.time())
            _private_write_json(self.admin_file, doc)
            return doc["generation"]

    # -- API tokens ---------------------------------------------------------------
    def _tokens(self) -> list[dict]:
        return list(self._read_json(self.tokens_file, []))

    def create_token(self, name: str) -> tuple[dict, str]:
        name = str(name or "").strip()[:60] or "script"
        token = "isk_" + secrets.token_urlsafe(32)
        rec = {"id": secrets.token_hex(4), "name": name, "created": time.time(),
               "sha256": hashlib.sha256(token.encode()).hexdigest()}
        with self._lock:
            tokens = self._tokens()
            tokens.append(rec)
            _private_write_json(self.tokens_file, tokens)
        return self._public(rec), token

    def list_tokens(self) -> list[dict]:
        return [self._public(t) for t in self._tokens()]

    def revoke_token(self, token_id: str) -> bool:
        with self._lock:
            tokens = self._tokens()
            kept = [t for t in tokens if t["id"] != token_id]
            if len(kept) == len(tokens):
                return False
            _private_write_json(self.tokens_file, kept)
            return True

    def token_valid(self, token: str) -> dict | None:
        if not token.startswith("isk_"):
            return None
        digest = hashlib.sha256(token.encode()).hexdigest()
        found = None
        for t in self._tokens():          # compare all, constant time each
            if hmac.compare_digest(t["sha256"], digest):
                found = t
        return found

    @staticmethod
    def _public(rec):
        return {k: rec[k] for k in ("id", "name", "created")}


def secret_key(folder) -> bytes:
    """The session-signing key, made once and kept (0600) so restarts keep people logged in."""
    path = Path(folder) / "secret_key"
    if not path.exists():
        write_bytes(path, secrets.token_bytes(32))
        os.chmod(path, 0o600)
    return path.read_bytes()


class LoginLimiter:
    """At most `attempts` failed logins per client address within `window_s` seconds."""

    def __init__(self, attempts=5, window_s=300.0, clock=time.monotonic):
        self.attempts, self.window_s, self.clock = attempts, window_s, clock
        self._fails: dict[str, deque] = defaultdict(deque)
        self._lock = threading.Lock()

    def _trim(self, q, now):
        while q and now - q[0] > self.window_s:
            q.popleft()

    def retry_after(self, who: str) -> float:
        """0 if `who` may try now, else seconds to wait."""
        with self._lock:
            now = self.clock()
            q = self._fails[who]
            self._trim(q, now)
            if len(q) < self.attempts:
                return 0.0
            return max(1.0, self.window_s - (now - q[0]))

    def failed(self, who: str):
        with self._lock:
            now = self.clock()
            q = self._fails[who]
            self._trim(q, now)
            q.append(now)
            if len(self._fails) > 10000:        # bound memory against address-spraying
                for k in [k for k, v in self._fails.items() if not v][:5000]:
                    del self._fails[k]

    def succeeded(self, who: str):
        with self._lock:
            self._fails.pop(who, None)


def first_login_done(cfg: dict) -> None:
    """Somebody logged in: the bench's display stops showing the first-run password."""
    from ..daemon import firstrun
    try:
        firstrun.done(cfg.get("bench_data_dir") or cfg["data_dir"])
    except OSError:
        pass                        # a read-only folder must not break the login


def new_csrf() -> str:
    return secrets.token_urlsafe(24)


def csrf_ok(expected: str | None, given: str | None) -> bool:
    return bool(expected) and bool(given) and hmac.compare_digest(str(expected), str(given))
