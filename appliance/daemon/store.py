"""The job store: SQLite for jobs, settings, calibration history and events;
plain folders for the scans and outputs (data_dir/jobs/<id>/).

The SD card of a Pi is the weak point. SQLite in WAL mode with
synchronous=FULL commits each transaction durably before it returns, and a
half-written transaction is rolled back on the next open, so a power cut
leaves the last committed state. Files go through atomicio (tmp, fsync,
rename). The order of writes makes the scan folder the truth about frames:
PNG first, then scan.json, then the job row; recovery only ever has to catch
the row up with scan.json, never the other way round.

A full disk is a fault like any other (DiskFull, where "disk"). SQLite rolls
a transaction back by itself when it cannot write, so our own ROLLBACK is
only sent while one is still open. The end of a job that could not be
written (failed, with its reason) is kept in memory, shown by get_job and
list_jobs as if stored, and written by flush_unwritten() as soon as there is
room again; events that could not be written wait in memory the same way.
Until the end is written the service refuses new scans and resumes.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
import time
from pathlib import Path

from ..errors import DeviceError, InkSliceError

log = logging.getLogger("inkslice.store")

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
_DISK_ERRORS = {sqlite3.SQLITE_FULL, sqlite3.SQLITE_IOERR}


class DiskFull(DeviceError):
    """SQLite could not write: the data disk is full (or failing). Nothing was half-written."""

    def __init__(self, detail: str):
        super().__init__(
            "disk",
            f"full: the job store cannot write ({detail}); free some space (delete old jobs), then resume",
        )


def _disk_fault(e: BaseException) -> DiskFull | None:
    if (
        isinstance(e, sqlite3.OperationalError)
        and (getattr(e, "sqlite_errorcode", None) or 0) & 0xFF in _DISK_ERRORS
    ):
        return DiskFull(str(e))
    return None


class Store:
    def __init__(self, data_dir):
        self.data_dir = Path(data_dir)
        self.jobs_dir = self.data_dir / "jobs"
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._db = sqlite3.connect(
            self.data_dir / "inkslice.db", check_same_thread=False, isolation_level=None, timeout=10
        )
        self._db.row_factory = sqlite3.Row
        try:
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.executescript(SCHEMA)
        except sqlite3.OperationalError as e:  # e.g. no room for the write-ahead log
            self._db.close()
            fault = _disk_fault(e)
            if fault is not None:
                raise fault from None
            raise
        self._unwritten: dict[str, dict] = {}  # job id -> its end (raw columns), not yet stored
        self._unwritten_events: list[tuple] = []

    def close(self):
        with self._lock:
            try:
                self.flush_unwritten()  # a job's end held back while the disk was full
            except DiskFull as e:
                log.warning(
                    "closing with %d job end(s) unwritten (%s); the next start marks those jobs interrupted",
                    len(self._unwritten),
                    e,
                )
            self._db.close()

    def _tx(self, sql, args=()):
        with self._lock:
            if self._unwritten or self._unwritten_events:
                self.flush_unwritten()
            return self._write([(sql, args)])

    def _write(self, statements):
        """The statements in one transaction; DiskFull when the disk cannot take it."""
        with self._lock:
            try:
                self._db.execute("BEGIN IMMEDIATE")
                cur = None
                for sql, args in statements:
                    cur = self._db.execute(sql, args)
                self._db.execute("COMMIT")
                return cur
            except BaseException as e:
                if self._db.in_transaction:  # SQLite may have rolled back already
                    try:
                        self._db.execute("ROLLBACK")
                    except sqlite3.Error as again:
                        log.warning("rollback after %s: %s", e, again)
                fault = _disk_fault(e)
                if fault is not None:
                    raise fault from e
                raise

    def flush_unwritten(self) -> None:
        """Write what a full disk held back (jobs' ends, then events); DiskFull while it still cannot."""
        with self._lock:
            for job_id, cols in list(self._unwritten.items()):
                names = ", ".join(f"{k} = ?" for k in cols)
                self._write([(f"UPDATE jobs SET {names} WHERE id = ?", (*cols.values(), job_id))])
                del self._unwritten[job_id]
                log.info(
                    "job %s: its end (%s) is written now that the disk has room", job_id, cols.get("status")
                )
            if self._unwritten_events:
                self._write(
                    [
                        ("INSERT INTO events (time, job_id, kind, message) VALUES (?, ?, ?, ?)", ev)
                        for ev in self._unwritten_events
                    ]
                )
                self._unwritten_events.clear()

    def unwritten(self) -> dict[str, dict]:
        """Jobs whose end is only in memory (the disk was full): id -> status, reason."""
        with self._lock:
            return {
                k: {"status": v.get("status"), "reason": v.get("reason", "")}
                for k, v in self._unwritten.items()
            }

    def integrity_ok(self) -> bool:
        with self._lock:
            return self._db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"

    # -- jobs -------------------------------------------------------------------
    def job_dir(self, job_id: str) -> Path:
        return self.jobs_dir / job_id

    def create_job(self, job_id, name, settings, params, levels_total):
        now = time.time()
        self._tx(
            "INSERT INTO jobs (id, name, status, created, started, settings, params, levels_total) "
            "VALUES (?, ?, 'homing', ?, ?, ?, ?, ?)",
            (job_id, name, now, now, json.dumps(settings), json.dumps(params), levels_total),
        )
        self.event(job_id, "created", f"scan {name!r} created")

    def update_job(self, job_id, **fields):
        if not fields:
            return
        for k in _JSON_COLS:
            if k in fields:
                fields[k] = json.dumps(fields[k])
        cols = ", ".join(f"{k} = ?" for k in fields)
        try:
            self._tx(f"UPDATE jobs SET {cols} WHERE id = ?", (*fields.values(), job_id))
        except DiskFull:
            if fields.get("status") in FINAL:  # the job is over: say so now, write it later
                with self._lock:
                    self._unwritten[job_id] = {**self._unwritten.get(job_id, {}), **fields}
            raise

    def delete_job(self, job_id) -> None:
        """The job's row and its events (its folder is the caller's to remove)."""
        self._write(
            [("DELETE FROM events WHERE job_id = ?", (job_id,)), ("DELETE FROM jobs WHERE id = ?", (job_id,))]
        )
        with self._lock:
            self._unwritten.pop(job_id, None)

    def get_job(self, job_id) -> dict:
        with self._lock:
            row = self._db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                raise InkSliceError(f"job {job_id}", "no such job")
            return self._row(row)

    def list_jobs(self, statuses=None) -> list[dict]:
        with self._lock:
            if statuses and not self._unwritten:
                q = f"SELECT * FROM jobs WHERE status IN ({','.join('?' * len(statuses))}) ORDER BY created DESC"
                rows = self._db.execute(q, tuple(statuses)).fetchall()
            else:
                rows = self._db.execute("SELECT * FROM jobs ORDER BY created DESC").fetchall()
            jobs = [self._row(r) for r in rows]
        return [j for j in jobs if not statuses or j["status"] in statuses]

    def _row(self, row) -> dict:
        d = {**dict(row), **self._unwritten.get(row["id"], {})}
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
            if self._unwritten or self._unwritten_events:
                self.flush_unwritten()
            self._write(
                [
                    ("INSERT OR REPLACE INTO settings (key, value) VALUES (?, ?)", (k, json.dumps(v)))
                    for k, v in settings.items()
                ]
            )

    # -- calibration history ------------------------------------------------------
    def add_calibration(self, data: dict, when: float | None = None):
        """A calibration result, dated now (or `when`: an imported one keeps its date). The newest
        row, in the order they were added, is the one in force."""
        self._tx(
            "INSERT INTO calibration (time, data) VALUES (?, ?)",
            (time.time() if when is None else float(when), json.dumps(data)),
        )

    def calibrations(self) -> list[dict]:
        with self._lock:
            rows = self._db.execute("SELECT time, data FROM calibration ORDER BY id DESC").fetchall()
        return [{"time": r["time"], **json.loads(r["data"])} for r in rows]

    def replace_calibrations(self, records: list[dict]):
        """The whole calibration history replaced at once (a restored backup): `records` as
        calibrations() returns them, newest first. One transaction: all or nothing."""
        rows = [
            (float(r["time"]), json.dumps({k: v for k, v in r.items() if k != "time"}))
            for r in reversed(records)
        ]  # oldest first, so the newest gets the highest id
        with self._lock:
            if self._unwritten or self._unwritten_events:
                self.flush_unwritten()
            self._write(
                [("DELETE FROM calibration", ())]
                + [("INSERT INTO calibration (time, data) VALUES (?, ?)", row) for row in rows]
            )

    # -- events -------------------------------------------------------------------
    def event(self, job_id, kind, message):
        """Logged now, or (the disk full) kept in memory and written with the next write that fits."""
        ev = (time.time(), job_id, kind, message)
        try:
            self._tx("INSERT INTO events (time, job_id, kind, message) VALUES (?, ?, ?, ?)", ev)
        except DiskFull:
            with self._lock:
                self._unwritten_events.append(ev)

    def events(self, job_id=None, limit=200) -> list[dict]:
        with self._lock:
            if job_id:
                rows = self._db.execute(
                    "SELECT * FROM events WHERE job_id = ? ORDER BY id DESC LIMIT ?", (job_id, limit)
                ).fetchall()
            else:
                rows = self._db.execute("SELECT * FROM events ORDER BY id DESC LIMIT ?", (limit,)).fetchall()
        return [dict(r) for r in rows]
