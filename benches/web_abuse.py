"""What a stranger on the LAN can do to the web server, measured against the real thing.

Starts `inkslice serve --fake` on loopback (a fresh data folder, nothing else is touched),
attacks it the ways issue 19 found, and prints one line per figure:

  disk      bytes the server holds on disk (its data folder plus every file it has open,
            unlinked spool files included) while anonymous clients send big bodies;
            target <= 1 MiB per request. A logged-in 8 MiB body is sent first as a
            control: it must show up, or the instrument is blind.
  memory    the server's resident memory (peak) while 50 clients, each from its own
            loopback address, send a wrong password at the same moment; target < 250 MB
  idle      p50/p99 of a logged-in request while 300 half-sent requests hold sockets
            open (from six loopback addresses); target p99 < 500 ms
  logout    a copy of a session cookie, used after that session logged out; must be 401

Loopback only, bounded: each phase has its own deadline and the whole run stops by itself
within about two minutes. Run: `PYTHONPATH=$PWD .venv/bin/python benches/web_abuse.py [--quick]`
(--quick: 2 anonymous bodies and 50 timed requests instead of 5 and 200). Exits 1 if a
target is missed.
"""

from __future__ import annotations

import argparse
import http.client
import os
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from pathlib import Path

MiB = 1024 * 1024
ANON_REQUESTS = 5
ANON_BODY = 100 * MiB  # announced by each anonymous request (under the 256 MiB upload cap)
LOGINS = 50
IDLE = 300
TIMED = 200


def start_server(data: Path):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "appliance.cli",
            "serve",
            "--fake",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--data",
            str(data),
            "--no-usb",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    url_line, pw_line = proc.stdout.readline(), proc.stdout.readline()
    port = int(re.search(r"127\.0\.0\.1:(\d+)/", url_line).group(1))
    password = re.search(r"password: (\S+)", pw_line).group(1)
    return proc, port, password


MISSED = []


def verdict(ok: bool, what: str) -> str:
    if not ok:
        MISSED.append(what)
    return "OK" if ok else "FAIL"


def request(port, method, path, body=b"", headers=None, src="127.0.0.1", timeout=10):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout, source_address=(src, 0))
    try:
        c.request(method, path, body=body, headers=headers or {})
        r = c.getresponse()
        return r.status, dict(r.getheaders()), r.read()
    finally:
        c.close()


def cookie_of(headers):
    return headers.get("Set-Cookie", "").split(";", 1)[0]


def csrf_in(page: bytes):
    return re.search(rb'name="csrf-token" content="([^"]+)"', page).group(1).decode()


def login(port, password, src="127.0.0.1"):
    """(cookie, csrf) of a fresh logged-in session."""
    _, h, page = request(port, "GET", "/login", src=src)
    cookie, csrf = cookie_of(h), csrf_in(page)
    form = urllib.parse.urlencode({"password": password, "csrf_token": csrf})
    status, h, _ = request(
        port,
        "POST",
        "/login",
        form,
        {"Cookie": cookie, "Content-Type": "application/x-www-form-urlencoded"},
        src=src,
    )
    assert status == 302, status
    cookie = cookie_of(h)
    _, _, page = request(port, "GET", "/", headers={"Cookie": cookie})
    return cookie, csrf_in(page)


# -- instruments -------------------------------------------------------------------------------


def disk_held(pid: int, data: Path) -> int:
    """Bytes in the data folder plus bytes in every regular file the server has open."""
    total = sum(p.stat().st_size for p in data.rglob("*") if p.is_file() and not p.is_symlink())
    fds = Path(f"/proc/{pid}/fd")
    for fd in fds.iterdir():
        try:
            st = os.stat(fd)
            target = os.readlink(fd)
        except OSError:
            continue
        if os.path.isabs(target.split(" (deleted)")[0]) and (
            target.endswith("(deleted)") or not target.startswith(str(data))
        ):
            if not target.startswith(("/dev", "/proc")) and (st.st_mode & 0o170000) == 0o100000:
                total += st.st_size
    return total


def rss(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


class Peak(threading.Thread):
    """Samples fn() every 5 ms until stopped; .peak is the largest value seen."""

    def __init__(self, fn):
        super().__init__(daemon=True)
        self.fn, self.peak, self.stop_ = fn, 0, threading.Event()

    def run(self):
        while not self.stop_.is_set():
            try:
                self.peak = max(self.peak, self.fn())
            except OSError:
                pass
            time.sleep(0.005)

    def stop(self):
        self.stop_.set()
        self.join()
        return self.peak


# -- attacks ---------------------------------------------------------------------------------------


def push_body(port, head: bytes, size: int, deadline_s: float, src="127.0.0.1") -> str:
    """Send headers then up to `size` bytes of body, until the server answers or hangs up."""
    s = socket.create_connection(("127.0.0.1", port), timeout=deadline_s, source_address=(src, 0))
    s.sendall(head)
    sent, block, end = 0, b"\0" * (256 * 1024), time.monotonic() + deadline_s
    s.setblocking(False)
    answer = b""
    try:
        while sent < size and time.monotonic() < end:
            try:
                answer += s.recv(4096)
                if answer:
                    break
            except BlockingIOError:
                pass
            try:
                sent += s.send(block[: size - sent])
            except BlockingIOError:
                time.sleep(0.001)
        s.settimeout(max(0.1, end - time.monotonic()))
        while b"\r\n" not in answer:
            more = s.recv(4096)
            if not more:
                break
            answer += more
    except (ConnectionResetError, BrokenPipeError, TimeoutError, OSError):
        pass
    finally:
        s.close()
    status = answer.split(b" ", 2)[1].decode() if answer.startswith(b"HTTP/") else "reset"
    return f"{status} after {sent / MiB:.1f} MiB"


def bench_disk(pid, port, data, token):
    control = Peak(lambda: disk_held(pid, data))
    base = disk_held(pid, data)
    control.start()
    head = (
        f"POST /api/uploads/scan HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {token}\r\n"
        f"Content-Type: application/zip\r\nContent-Length: {8 * MiB}\r\n\r\n"
    ).encode()
    ctl = push_body(port, head, 8 * MiB, 20)
    ctl_peak = control.stop() - base
    peak = Peak(lambda: disk_held(pid, data))
    base = disk_held(pid, data)
    peak.start()
    results = []
    threads = [
        threading.Thread(
            target=lambda i=i: results.append(
                push_body(
                    port,
                    (
                        f"POST /login HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n"
                        f"Content-Length: {ANON_BODY}\r\n\r\n"
                    ).encode(),
                    ANON_BODY,
                    15,
                    src=f"127.0.1.{i + 1}",
                )
            )
        )
        for i in range(ANON_REQUESTS)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    used = peak.stop() - base
    print(
        f"control   a logged-in 8 MiB body: {ctl}; disk held at its peak {ctl_peak / MiB:.1f} MiB "
        "(the instrument sees spooled bodies)"
    )
    print(
        f"disk      {ANON_REQUESTS} anonymous bodies of {ANON_BODY // MiB} MiB: answered {sorted(set(results))}; "
        f"peak disk held {used / MiB:.3f} MiB = {used / ANON_REQUESTS / MiB:.3f} MiB per request "
        f"(target <= 1 MiB)  {verdict(used <= ANON_REQUESTS * MiB, 'disk')}"
    )


def bench_logins(pid, port):
    forms = []
    for i in range(LOGINS):
        src = f"127.0.2.{i + 1}"
        _, h, page = request(port, "GET", "/login", src=src)
        forms.append((src, cookie_of(h), csrf_in(page)))
    base = rss(pid)
    peak = Peak(lambda: rss(pid))
    peak.start()
    go, codes = threading.Barrier(LOGINS), []

    def attempt(src, cookie, csrf):
        body = urllib.parse.urlencode({"password": "wrong-password", "csrf_token": csrf})
        go.wait()
        codes.append(
            request(
                port,
                "POST",
                "/login",
                body,
                {"Cookie": cookie, "Content-Type": "application/x-www-form-urlencoded"},
                src=src,
            )[0]
        )

    t0 = time.monotonic()
    threads = [threading.Thread(target=attempt, args=f) for f in forms]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    took = time.monotonic() - t0
    time.sleep(0.2)
    top = peak.stop()
    counts = {c: codes.count(c) for c in sorted(set(codes))}
    print(
        f"memory    {LOGINS} parallel wrong logins from {LOGINS} addresses in {took:.2f} s: answers {counts}; "
        f"RSS {base / MiB:.0f} MB before, peak {top / MiB:.0f} MB (target < 250 MB)  "
        f"{verdict(top < 250 * MiB, 'memory')}"
    )


def bench_idle(port, cookie):
    idle = []
    for i in range(IDLE):
        s = socket.create_connection(
            ("127.0.0.1", port), timeout=5, source_address=(f"127.0.3.{1 + i % 6}", 0)
        )
        s.sendall(b"GET /api/state HTTP/1.1\r\nHost: x\r\n")  # and never the blank line
        idle.append(s)
    time.sleep(0.5)
    times, codes = [], []
    end = time.monotonic() + 60
    for _ in range(TIMED):
        if time.monotonic() > end:
            break
        t0 = time.monotonic()
        try:
            codes.append(request(port, "GET", "/api/state", headers={"Cookie": cookie}, timeout=5)[0])
        except OSError:
            codes.append("timeout")
        times.append(time.monotonic() - t0)
    still_open = 0
    for s in idle:
        s.setblocking(False)
        try:
            still_open += s.recv(1) != b""
        except BlockingIOError:
            still_open += 1
        except OSError:
            pass
        s.close()
    times.sort()
    p50, p99 = times[len(times) // 2], times[min(len(times) - 1, int(len(times) * 0.99))]
    ok = codes.count(200)
    print(
        f"idle      {IDLE} half-sent requests ({still_open} still held open at the end); {ok}/{len(codes)} "
        f"logged-in requests answered 200, p50 {p50 * 1000:.1f} ms, p99 {p99 * 1000:.1f} ms "
        f"(target < 500 ms)  {verdict(p99 < 0.5 and ok == len(codes), 'idle')}"
    )


def bench_logout(port, password):
    cookie, csrf = login(port, password)
    before = request(port, "GET", "/api/state", headers={"Cookie": cookie})[0]
    request(
        port,
        "POST",
        "/logout",
        urllib.parse.urlencode({"csrf_token": csrf}),
        {"Cookie": cookie, "Content-Type": "application/x-www-form-urlencoded"},
    )
    after = request(port, "GET", "/api/state", headers={"Cookie": cookie})[0]
    print(
        f"logout    a copied cookie: {before} before logout, {after} after  {verdict(after == 401, 'logout')}"
    )


def main():
    global ANON_REQUESTS, TIMED
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer anonymous bodies and timed requests")
    if ap.parse_args().quick:
        ANON_REQUESTS, TIMED = 2, 50
    with tempfile.TemporaryDirectory(prefix="inkslice-web-abuse-") as tmp:
        data = Path(tmp) / "data"
        proc, port, password = start_server(data)
        stop_at = threading.Timer(150, proc.kill)  # the whole run is bounded, whatever hangs
        stop_at.start()
        try:
            from appliance.web.auth import Credentials

            token = Credentials(data / "web").create_token("bench")[1]
            cookie, _ = login(port, password)  # before the login storm (its limits lock logins)
            print(
                f"server    pid {proc.pid}, http://127.0.0.1:{port}/, RSS {rss(proc.pid) / MiB:.0f} MB idle"
            )
            bench_disk(proc.pid, port, data, token)
            bench_logins(proc.pid, port)
            bench_idle(port, cookie)
            bench_logout(port, password)
        finally:
            stop_at.cancel()
            proc.terminate()
            proc.wait(timeout=10)
    if MISSED:
        print(f"missed: {', '.join(MISSED)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
