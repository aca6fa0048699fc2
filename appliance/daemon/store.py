"""The job store: SQLite for jobs, settings, calibration history and events;
plain folders for the scans and outputs (data_dir/jobs/<id>/).

The SD card of a Pi is the weak point. SQLite in WAL mode with
synchronous=FULL commits each transaction durably before it returns, and a
half-written transaction is rolled back on the next open, so a power cut
leaves the last committed state. Files go through atomicio (tmp, fsync,
rename). The order of writes makes the scan folder the truth about frames:
PNG first, then scan.json, then the job row; recovery only ever has to catch
the row up with scan.json, never the other way round.
"""
from __future__ import annotations

import json
import sqlite3
import threading
import time
from pathlib import Path

from ..errors import InkSliceError

SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL DEFAULT '',
    status TEXT NOT NULL,
    reason TEXT NOT NULL DEFAULT '',
    interrupted INTEGER NOT NULL DEFAULT 0,
    created REAL NOT NULL,
    started REAL,
    finished REAL,
    settings TEXT NOT NULL,
    params TEXT NOT NULL,
    levels_done INTEGER NOT NULL DEFAULT 0,
    levels_total INTEGER NOT NULL DEFAULT 0,
    level_mm REAL,
    attempts INTEGER NOT NULL DEFAULT 1,
    outputs TEXT NOT NULL DEFAULT '[]'
);
CREATE TABLE IF NOT EXISTS settings (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS calibration (
    id INTEGER PRIMARY KEY AUTOINCREMENT, time REAL NOT NULL, data TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY AUTOINCREMENT, time REAL NOT NULL, job_id TEXT,
    kind TEXT NOT NULL, message TEXT NOT NULL);
"""
ACTIVE = ("homing", "scanning", "processing")
FINAL = ("done", "failed", "cancelled")
_JSON_COLS = ("settings", "params", "outputs")


class Store:
    def __init__(self, data_dir):
        self.data_dir = Path(data_dir)
        self.jobs_dir = self.data_dir / "jobs"
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._db = sqlite3.connect(self.data_dir / "inkslice.db", check_same_thread=False,
                                   isolation_level=None, timeout=10)
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        self._db.executescript(SCHEMA)

    def close(self):
        with self._lock:
            self._db.close()

    def _tx(self, sql, args=()):
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                cur = self._db.execute(sql, args)
                self._db.execute("COMMIT")
                return cur
            except BaseException:
                self._db.execute("ROLLBACK")
                raise

    def integrity_ok(self) -> bool:
        with self._lock:
            return self._db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"

    # -- jobs -------------------------------------------------------------------
    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def create_job(self, job_id, name, settings, params, levels_total):
        now = time.time()
        self._tx("INSERT INTO jobs (id, name, status, created, started, settings, params, levels_total) "
                 "VALUES (?, ?, 'homing', ?, ?, ?, ?, ?)",
                 (job_id, name, now, now, json.dumps(settings), json.dumps(params), levels_total))
        self.event(job_id, "created", f"scan {name!r} created")

    def update_job(self, job_id, **fields):
        if not fields:
            return
        for k in _JSON_COLS:
            if k in fields:
                fields[k] = json.dumps(fields[k])
        cols = ", ".join(f"{k} = ?" for k in fields)
        self._tx(f"UPDATE jobs SET {cols} WHERE id = ?", (*fields.values(), job_id))

    def get_job(self, job_id) -> dict:
        with self._lock:
            row = self._db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            raise InkSliceError(f"job {job_id}", "no such job")
        return self._row(row)

    def list_jobs(self, statuses=None) -> list[dict]:
        with self._lock:
            if statuses:
                q = f"SELECT * FROM jobs WHERE status IN ({','.join('?' * len(statuses))}) ORDER BY created DESC"
                rows = self._db.execute(q, tuple(statuses)).fetchall()
            else:
                rows = self._db.execute("SELECT * FROM jobs ORDER BY created DESC").fetchall()
        return [self._row(r) for r in rows]

    @staticmethod
    def _row(row) -> dict:
        d = dict(row)
        for k in _JSON_COLS:
            d[k] = json.loads(d[k])
        d["interrupted"] = bool(d["interrupted"])
        return d

    # -- settings -----------------------------------------------------------------
    def load_settings(self) -> dict:
        with self._lock:
            rows = self._db.execute("SELECT key, value FROM settings").fetchall()
        return {r["key"]: json.loads(r["value"]) for r in rows}

    def save_settings(self, settings: dict):
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                for k, v in settings.items():
                    self._db.execute("INSERT OR REPLACE INTO settings (key, value) VALUES (?, ?)",
                                     (k, json.dumps(v)))
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise

    # -- calibration history ------------------------------------------------------
    def add_calibration(self, data: dict, when: float | None = None):
        """A calibration result, dated now (or `when`: an imported one keeps its date). The newest
        row, in the order they were added, is the one in force."""
        self._tx("INSERT INTO calibration (time, data) VALUES (?, ?)",
                 (time.time() if when is None else float(when), json.dumps(data)))

    def calibrations(self) -> list[dict]:
        with self._lock:
            rows = self._db.execute("SELECT time, data FROM calibration ORDER BY id DESC").fetchall()
        return [{"time": r["time"], **json.loads(r["data"])} for r in rows]

    # -- events -------------------------------------------------------------------
    def event(self, job_id, kind, message):
        self._tx("INSERT INTO events (time, job_id, kind, message) VALUES (?, ?, ?, ?)",
                 (time.time(), job_id, kind, message))

    def events(self, job_id=None, limit=200) -> list[dict]:
        with self._lock:
            if job_id:
                rows = self._db.execute("SELECT * FROM events WHERE job_id = ? ORDER BY id DESC LIMIT ?",
                                        (job_id, limit)).fetchall()
            else:
                rows = self._db.execute("SELECT * FROM events ORDER BY id DESC LIMIT ?", (limit,)).fetchall()
        return [dict(r) for r in rows]
