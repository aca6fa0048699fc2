"""What the daemon offers the web UI, the CLI and the socket: the one definition.

`Bench` is a `typing.Protocol`. The daemon's BenchService implements it in-process;
rpc.BenchClient implements it over the daemon's socket; web/adapter.py is typed against
it and cannot tell the two apart. rpc.METHODS (what the socket serves) is derived from
it, so a method added here is served at once and a method nobody declared is not.

A method's arguments and results are plain JSON values (dicts, lists, strings, numbers)
so they cross the socket unchanged; the two exceptions, latest_frame's JPEG bytes and
job_file's Path, are encoded by rpc.py. Errors are the appliance's own (errors.py):
SettingError for bad input, DeviceError when the bench cannot, InkSliceError otherwise.

A method marked @reads only reads: the socket's client may send it again on a fresh
connection when the daemon restarted under it, since doing it twice changes nothing
(rpc.BenchClient.READ_ONLY is read_only()).

`differences(cls)` compares a class with the protocol by name and parameters; the
tests run it on BenchService and BenchClient (tests/test_facade.py). An implementation
may take extra trailing parameters with defaults (BenchService.cancel's wait) that only
in-process callers use.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, Protocol, TypeVar

# Facade methods that are not plain request/reply calls over the socket: subscribe streams
# (rpc.py serves it on its own), close lets go of the caller's own handle.
NOT_CALLS = ("subscribe", "close")

_Method = TypeVar("_Method", bound=Callable[..., Any])


def reads(method: _Method) -> _Method:
    """Marks a facade method that changes nothing: safe to send twice."""
    method.reads_only = True  # type: ignore[attr-defined]
    return method


class Bench(Protocol):
    # -- the bench's state and the scan ---------------------------------------------------
    @reads
    def state(self) -> dict:
        """The bench now: state, job_id, level, progress, ETA, message, hardware, notice, manual."""
        ...

    def subscribe(self, timeout: float = 30.0) -> Iterator[dict]:
        """The state now and on every change, for at most `timeout` seconds."""
        ...

    def start_scan(self, params: dict) -> str:
        """Start a scan with these settings (and the bench's extras, e.g. name); its job id."""
        ...

    def cancel(self) -> None:
        """Stop the scan, calibration or commissioning step in progress; no-op when idle."""
        ...

    def resume(self, job_id: str) -> str:
        """Continue a failed, cancelled or interrupted scan where it stopped."""
        ...

    @reads
    def latest_frame(self) -> tuple[bytes, dict] | None:
        """The newest camera frame as JPEG with its info (level, time); None before any."""
        ...

    @reads
    def live_heightmap(self) -> dict | None:
        """The current (or last) scan's height map so far; None before the first frame."""
        ...

    # -- jobs -----------------------------------------------------------------------------
    @reads
    def jobs(self) -> list[dict]:
        """Every job, newest first."""
        ...

    @reads
    def job(self, job_id: str) -> dict:
        """One job's record: status, params, outputs, levels, times."""
        ...

    @reads
    def job_file(self, job_id: str, name: str) -> Path:
        """A file inside that job's folder (outputs, scan/scan.json, scan/frames/...); nothing else."""
        ...

    @reads
    def job_sizes(self) -> dict[str, int]:
        """Bytes on disk per job."""
        ...

    @reads
    def events(self, job_id: str | None = None, limit: int = 200) -> list[dict]:
        """The event log, newest first (one job's, or the whole box's)."""
        ...

    def rename_job(self, job_id: str, name: str) -> dict:
        """Give a job another name; the job's record."""
        ...

    def delete_job(self, job_id: str) -> None:
        """The job's record and its whole folder; not while it runs."""
        ...

    def reprocess(self, job_id: str, changes: dict | None = None) -> str:
        """Process a kept scan again with its settings changed by `changes`."""
        ...

    def repost(self, job_id: str, options: dict | None = None) -> list[str]:
        """New G-code from the job's height map (cutter, material, dialect); the files written."""
        ...

    def import_scan(self, folder: str | Path) -> str:
        """A scan folder from elsewhere becomes a job and is processed; its job id."""
        ...

    # -- settings, calibration, commissioning ---------------------------------------------
    @reads
    def settings(self) -> dict:
        """Every setting in force (docs/settings.md)."""
        ...

    def update_settings(self, changes: dict) -> dict:
        """Validate and save these changes; every setting in force after them."""
        ...

    @reads
    def calibration(self) -> dict:
        """The guided plane calibration: its step and what it found."""
        ...

    def calibrate(self, step: str) -> dict:
        """Do one guided calibration step (home, target, detect, accept); calibration()."""
        ...

    @reads
    def commissioning(self) -> dict:
        """Every commissioning step's result in force with its date, the step in progress."""
        ...

    def commission(self, step: str, action: str, values: dict | None = None) -> dict:
        """One action of one commissioning step (docs/api/README.md); commissioning()."""
        ...

    @reads
    def export_commissioning(self) -> dict:
        """The commissioning results as one document."""
        ...

    def import_commissioning(self, doc: dict) -> dict:
        """Take the results of an exported commissioning document; commissioning()."""
        ...

    def ink_changed(self) -> dict:
        """Note an ink change (steps measured before it are stale); commissioning()."""
        ...

    # -- the machine panel between scans --------------------------------------------------
    def preview(self) -> dict:
        """Keep the panel's session and light on; a fresh frame in latest_frame()."""
        ...

    def home_stage(self) -> dict:
        """Home the stage; the panel's state."""
        ...

    def jog(self, mm: float) -> dict:
        """Lift the base by mm (negative: lower it); the panel's state."""
        ...

    def goto_level(self, level_mm: float) -> dict:
        """Move the base top to this level; the panel's state."""
        ...

    # -- the box: USB, backup, system, webhook --------------------------------------------
    @reads
    def usb_sticks(self) -> list[dict]:
        """The USB sticks plugged in; none when USB export is off."""
        ...

    def export_to_usb(
        self, job_id: str, name: str = "toolpath.gcode", stick: str | None = None, release: bool = True
    ) -> dict:
        """Copy a job's file onto a stick (None: the first), verified, then unmounted."""
        ...

    @reads
    def backup(self) -> dict:
        """The settings and the calibration history as one document."""
        ...

    def restore(self, doc: dict) -> dict:
        """Replace the settings and calibration history by a backup's."""
        ...

    @reads
    def system(self) -> dict:
        """Version, uptimes, the data disk, the number of jobs, the last webhook delivery."""
        ...

    def test_webhook(self) -> dict:
        """POST a test message to the webhook address now; {"ok", "problem"}."""
        ...

    def close(self) -> None:
        """Let go of this handle (the daemon: stop the bench; a client: its connections)."""
        ...


def methods() -> tuple[str, ...]:
    """The facade's method names, in the order written above."""
    return tuple(name for name in vars(Bench) if not name.startswith("_") and callable(vars(Bench)[name]))


def read_only() -> frozenset[str]:
    """The facade methods marked @reads."""
    return frozenset(name for name in methods() if getattr(vars(Bench)[name], "reads_only", False))


def calls() -> tuple[str, ...]:
    """The facade methods served as request/reply over the socket (rpc.METHODS)."""
    return tuple(name for name in methods() if name not in NOT_CALLS)


_Class = TypeVar("_Class", bound=type)


def forwards(via: str) -> Callable[[_Class], _Class]:
    """A class decorator for a stand-in of the facade (the socket's client, the web's wrapper):
    every request/reply call the class does not write out itself becomes one that hands its
    name and arguments to the class's method `via`, `via(name, *args, **kwargs)`. The method
    carries the facade's signature, docstring and @reads mark (inspect.signature follows its
    __wrapped__), so differences() and help() see the facade's method."""

    def fill(cls: _Class) -> _Class:
        for name in calls():
            if name not in vars(cls):
                setattr(cls, name, _forwarder(name, via))
        return cls

    return fill


def _forwarder(name: str, via: str) -> Callable[..., Any]:
    def method(self, *args, **kwargs):
        return getattr(self, via)(name, *args, **kwargs)

    return functools.wraps(getattr(Bench, name))(method)


def _parameters(fn) -> list[inspect.Parameter]:
    return list(inspect.signature(fn).parameters.values())[1:]  # without self


def _shape(p: inspect.Parameter) -> tuple:
    return p.name, p.kind, p.default


def differences(cls: type) -> list[str]:
    """How `cls` departs from the facade: a missing method, a parameter renamed, moved,
    added without a default or with another default. Empty when it implements Bench."""
    found = []
    for name in methods():
        impl = getattr(cls, name, None)
        if not callable(impl):
            found.append(f"{cls.__name__}.{name}: missing")
            continue
        want, have = _parameters(getattr(Bench, name)), _parameters(impl)
        if [_shape(p) for p in have[: len(want)]] != [_shape(p) for p in want]:
            facade = inspect.signature(getattr(Bench, name))
            found.append(f"{cls.__name__}.{name}{inspect.signature(impl)}: the facade has {name}{facade}")
        elif any(p.default is inspect.Parameter.empty for p in have[len(want) :]):
            found.append(f"{cls.__name__}.{name}: an extra parameter without a default")
    return found
