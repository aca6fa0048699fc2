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
- Login rate limit (LoginLimiter): per client address, at most N failures in
  a sliding window, and a ceiling for all addresses together; past that every
  attempt (even a right one) gets 429 until the window has moved on. An
  attempt counts as failed before its hash is checked, and at most two hashes
  run at once (scrypt takes 32 MiB each). /api/password, which checks the
  current password, goes through the same limiter.
- Sessions are also rows in DATA/web/sessions.sqlite (sessions.py): logout
  and a password change delete them, so a copied cookie stops working.
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

from flask import current_app, request
from werkzeug.security import check_password_hash, generate_password_hash

from ..atomicio import write_bytes, write_json
from ..daemon import firstrun

MIN_PASSWORD = 8
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


def _private_write_json(path: Path, obj):
    write_json(path, obj)
    os.chmod(path, 0o600)  # mkstemp already makes 0600; say it explicitly for the reader


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
            password = "-".join(secrets.token_urlsafe(12)[i : i + 4] for i in (0, 4, 8))
            _private_write_json(
                self.admin_file,
                {
                    "hash": generate_password_hash(password, "scrypt"),
                    "generation": 1,
                    "must_change": True,
                    "set": time.time(),
                },
            )
            return password

    def reset_generated(self) -> str:
        """A fresh generated password (the demo prints one every start); old sessions end."""
        with self._lock:
            old = self._read_json(self.admin_file, None) or {"generation": 0}
            password = "-".join(secrets.token_urlsafe(12)[i : i + 4] for i in (0, 4, 8))
            _private_write_json(
                self.admin_file,
                {
                    "hash": generate_password_hash(password, "scrypt"),
                    "generation": int(old["generation"]) + 1,
                    "must_change": True,
                    "set": time.time(),
                },
            )
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
            doc.update(
                hash=generate_password_hash(new, "scrypt"),
                generation=int(doc["generation"]) + 1,
                must_change=False,
                set=time.time(),
            )
            _private_write_json(self.admin_file, doc)
            return doc["generation"]

    # -- API tokens ---------------------------------------------------------------
    def _tokens(self) -> list[dict]:
        return list(self._read_json(self.tokens_file, []))

    def create_token(self, name: str) -> tuple[dict, str]:
        name = str(name or "").strip()[:60] or "script"
        token = "isk_" + secrets.token_urlsafe(32)
        rec = {
            "id": secrets.token_hex(4),
            "name": name,
            "created": time.time(),
            "sha256": hashlib.sha256(token.encode()).hexdigest(),
        }
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
        for t in self._tokens():  # compare all, constant time each
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
    """Password guessing, bounded three ways.

    - per client address: at most `attempts` failures within `window_s` seconds;
    - from everyone together: at most `global_attempts` failures in that window (an attacker
      with many addresses on the LAN still gets only so many guesses);
    - at most `hashes` password checks running at once (scrypt takes 32 MiB each; a burst of
      thirty would take a gigabyte). Past that, `try_hash()` says no and the caller answers
      429 at once instead of queueing.

    begin() counts the attempt as a failure BEFORE the hash is checked, so a burst of parallel
    requests cannot all slip in while the first checks are still running; succeeded() takes
    it back. checked_password() below puts the steps together.
    """

    def __init__(self, attempts=5, window_s=300.0, global_attempts=50, hashes=2, clock=time.monotonic):
        self.attempts, self.window_s, self.clock = attempts, window_s, clock
        self.global_attempts = global_attempts
        self._fails: dict[str, deque] = defaultdict(deque)
        self._all: deque = deque()
        self._lock = threading.Lock()
        self._hashing = threading.BoundedSemaphore(hashes)

    def _trim(self, q, now):
        while q and now - q[0] > self.window_s:
            q.popleft()

    def _wait(self, who, now) -> float:
        q = self._fails[who]
        self._trim(q, now)
        self._trim(self._all, now)
        waits = [
            self.window_s - (now - d[0])
            for d, cap in ((q, self.attempts), (self._all, self.global_attempts))
            if len(d) >= cap
        ]
        return max(1.0, max(waits)) if waits else 0.0

    def retry_after(self, who: str) -> float:
        """0 if `who` may try now, else seconds to wait."""
        with self._lock:
            return self._wait(who, self.clock())

    def begin(self, who: str) -> float:
        """Like retry_after, but a 0 also records the attempt as a failure (until succeeded())."""
        with self._lock:
            now = self.clock()
            wait = self._wait(who, now)
            if not wait:
                self._record(who, now)
            return wait

    def failed(self, who: str):
        with self._lock:
            now = self.clock()
            self._trim(self._fails[who], now)
            self._record(who, now)

    def _record(self, who, now):
        self._fails[who].append(now)
        self._all.append(now)
        if len(self._fails) > 10000:  # bound memory against address-spraying
            for k in [k for k, v in self._fails.items() if not v][:5000]:
                del self._fails[k]

    def succeeded(self, who: str):
        with self._lock:
            if self._fails.pop(who, None) and self._all:
                self._all.pop()  # the attempt begin() counted was not a failure

    def try_hash(self) -> bool:
        """Take one of the password-check slots without waiting; release with done_hash()."""
        return self._hashing.acquire(blocking=False)

    def done_hash(self):
        self._hashing.release()


def checked_password(
    limiter: LoginLimiter, creds: Credentials, who: str, password
) -> tuple[bool | None, float]:
    """(True, 0) right, (False, 0) wrong, (None, seconds) not checked: locked out or hashes busy."""
    if not limiter.try_hash():
        return None, 1.0
    try:
        wait = limiter.begin(who)
        if wait:
            return None, wait
        ok = creds.check_password(password)
        if ok:
            limiter.succeeded(who)
        return ok, 0.0
    finally:
        limiter.done_hash()


def first_login_done(cfg: dict) -> None:
    """Somebody logged in: the bench's display stops showing the first-run password."""
    try:
        firstrun.done(cfg.get("bench_data_dir") or cfg["data_dir"])
    except OSError:
        pass  # a read-only folder must not break the login


def current_config() -> dict:
    """The app's configuration (app.py's DEFAULTS with what create_app was given)."""
    return current_app.extensions["inkslice"]["config"]


def client_address() -> str:
    """Who is asking, for the login limiter: the peer, or behind a trusted proxy the address it saw."""
    if current_config().get("trusted_proxy"):
        # The proxy appends the address it saw to whatever the client sent: only the
        # right-most entry is the proxy's word, everything left of it is the client's.
        fwd = request.headers.get("X-Forwarded-For", "")
        last = fwd.rsplit(",", 1)[-1].strip()
        if last:
            return last
    return request.remote_addr or "?"


def new_csrf() -> str:
    return secrets.token_urlsafe(24)


def csrf_ok(expected: str | None, given: str | None) -> bool:
    return bool(expected) and bool(given) and hmac.compare_digest(str(expected), str(given))
