"""An installed copy works with no checkout beside it.

This is what `systemd/install.sh` gives a box: the sources copied to
/opt/inkslice, installed (not editable) into a venv of its own. The test lays
the files out with `install.sh --root`, builds the wheel from that copy,
installs it into a fresh venv in a temporary folder and runs everything from
there, with the working folder outside the checkout and the checkout nowhere
on the import path:
  - the protocol code table and the firmware sources come from the wheel;
  - the firmware builds into a cache folder (never into site-packages) and
    `inkslice firmware flash` hands avrdude the HEX;
  - both services run from the venv: the daemon on the simulated bench (the
    firmware under simavr, the virtual camera) and the web; a client logs in,
    commissions the box (commission(), below), scans a small part and gets
    the G-code.

To keep the wheel's dependencies from being downloaded again, the fresh venv
sees the test venv's site-packages through a .pth line (numpy, scipy, OpenCV,
Flask...). The checkout's editable install is not reachable that way: a path
added by a .pth line is not scanned for .pth files, so the editable finder
never loads, and the test asserts `appliance` comes from the fresh venv.
"""
from __future__ import annotations

import http.cookiejar
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
import urllib.error
import urllib.request
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.slow, pytest.mark.simavr,
              pytest.mark.skipif(shutil.which("avr-gcc") is None or shutil.which("simavr") is None,
                                 reason="needs gcc-avr and simavr (scripts/setup.sh)")]

# a small part: the cone (23.2 mm), 10 levels 2 mm apart from above its tip, read with the seed pipeline
SCAN = {"name": "installed copy: cone", "levels_to_mm": 24.0, "levels_from_mm": 6.0, "level_step_mm": 2.0,
        "settle_s": 0.0, "pipeline": "seed"}


@dataclass
class Installed:
    wheel: Path
    venv: Path
    site: Path               # the venv's site-packages, where the wheel went
    run_dir: Path            # the working folder of every process (not the checkout)
    env: dict
    shipped: list = None     # site_files() right after the install

    def site_files(self) -> list[Path]:
        """What the wheel put into site-packages (byte-code caches aside): nothing may add to it."""
        return sorted(p for p in (self.site / "appliance").rglob("*") if "__pycache__" not in p.parts)

    def bin(self, name: str) -> str:
        return str(self.venv / "bin" / name)

    def run(self, *args, **kw) -> subprocess.CompletedProcess:
        return subprocess.run(list(args), cwd=self.run_dir, env=self.env, capture_output=True, text=True,
                              timeout=kw.pop("timeout", 300), **kw)

    def start(self, *args) -> subprocess.Popen:
        return subprocess.Popen(list(args), cwd=self.run_dir, env=self.env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)


def laid_out(root: Path) -> Path:
    """The sources as `systemd/install.sh` copies them to the box (/opt/inkslice under root)."""
    r = subprocess.run([str(REPO / "systemd/install.sh"), "--root", str(root)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return root / "opt" / "inkslice"


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Installed:
    tmp = tmp_path_factory.mktemp("installed")
    src = laid_out(tmp / "root")
    wheel_dir = tmp / "dist"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheel_dir), str(src)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    wheel, = wheel_dir.glob("inkslice-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    (site / "shared-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    r = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", str(wheel)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    shutil.rmtree(tmp / "root")          # nothing of the sources is left to fall back on
    run_dir = tmp / "run"
    run_dir.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "INKSLICE_", "VIRTUAL_ENV"))}
    env.update(PATH=f"{venv / 'bin'}:{env.get('PATH', '/usr/bin:/bin')}", XDG_CACHE_HOME=str(tmp / "cache"),
               PYTHONUNBUFFERED="1")
    box = Installed(wheel, venv, site, run_dir, env)
    box.shipped = box.site_files()
    return box


def test_the_installed_copy_imports_from_its_own_venv_and_reads_the_protocol_table(installed):
    r = installed.run(installed.bin("python"), "-c", """if True:
        import json, os, sys
        import appliance, appliance.hw.protocol as P
        from appliance.firmware import codes_path
        print(json.dumps({"appliance": appliance.__file__, "cwd": os.getcwd(), "path": sys.path,
                          "codes": str(codes_path()), "settings": len(P.SETTINGS)}))""")
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    assert Path(got["appliance"]).is_relative_to(installed.site)
    assert Path(got["codes"]).is_relative_to(installed.site) and Path(got["codes"]).name == "codes.def"
    assert got["settings"] > 0
    assert not Path(got["cwd"]).is_relative_to(REPO)
    # the one path into the checkout allowed is the shared dependencies' site-packages (in CI the
    # test venv lives in the checkout): it holds numpy and friends, never a copy of `appliance`
    deps = Path(sysconfig.get_paths()["purelib"]).resolve()
    assert not (deps / "appliance").exists()
    assert not [p for p in got["path"] if p and Path(p).resolve().is_relative_to(REPO) and Path(p).resolve() != deps]


def test_the_wheel_holds_the_modules_of_the_checkout_and_what_they_need_at_run_time(installed):
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    tracked = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "appliance"], cwd=REPO, check=True,
                             capture_output=True, text=True).stdout.split()
    # every module, and nothing else (a stale build/ folder would add deleted ones)
    assert {n for n in names if n.endswith(".py")} == {n for n in tracked if n.endswith(".py")}
    fw = "appliance/firmware/stepper/"
    needed = {fw + "codes.def", fw + "Makefile", fw + "sim/hil.c", "appliance/web/static/chessboard.pdf",
              "appliance/web/static/chessboard.png"}
    needed |= {n for n in tracked if n.startswith((fw + "src/", "appliance/web/templates/", "appliance/web/static/"))}
    assert needed <= names, sorted(needed - names)
    assert not [n for n in names if "/build/" in n or n.endswith((".o", ".elf", ".hex"))], "build outputs shipped"


def test_the_installed_copy_builds_and_flashes_the_firmware(installed, tmp_path):
    """`inkslice firmware flash` builds the HEX into the cache and runs avrdude on it. avrdude
    itself is stood in for by a script that records what it was given (no board here)."""
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    record = tmp_path / "avrdude.json"
    (fake_bin / "avrdude").write_text(f"#!{sys.executable}\nimport json, sys\n"
                                      f"json.dump(sys.argv[1:], open({str(record)!r}, 'w'))\n")
    (fake_bin / "avrdude").chmod(0o755)
    env = {**installed.env, "PATH": f"{fake_bin}:{installed.env['PATH']}"}
    r = subprocess.run([installed.bin("inkslice"), "firmware", "flash", "--port", "/dev/ttyACM7"],
                       cwd=installed.run_dir, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "flashed /dev/ttyACM7" in r.stdout
    args = json.loads(record.read_text())
    assert args[:8] == ["-p", "m328p", "-c", "arduino", "-P", "/dev/ttyACM7", "-b", "115200"]
    hex_file = Path(re.fullmatch(r"flash:w:(.+):i", args[-1]).group(1))
    assert hex_file.is_relative_to(Path(installed.env["XDG_CACHE_HOME"]))
    lines = hex_file.read_text().splitlines()
    assert lines[0].startswith(":") and lines[-1] == ":00000001FF" and len(lines) > 100     # Intel HEX
    assert installed.site_files() == installed.shipped, "the build wrote into site-packages"


# ---- both services from the installed copy -------------------------------------------------------

class WebClient:
    """A browser's worth of HTTP: a cookie jar, the CSRF token, JSON in and out."""

    def __init__(self, url):
        self.url = url
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
        self.csrf = None

    def _csrf_of(self, path):
        page = self.opener.open(self.url + path, timeout=10).read().decode()
        return re.search(r'name="csrf-token" content="([^"]+)"', page).group(1)

    def login(self, password):
        form = urllib.parse.urlencode({"password": password, "csrf_token": self._csrf_of("/login")}).encode()
        self.opener.open(self.url + "/login", data=form, timeout=10)
        self.csrf = self._csrf_of("/")

    def call(self, method, path, body=None):
        req = urllib.request.Request(self.url + path, method=method,
                                     data=None if body is None else json.dumps(body).encode(),
                                     headers={"Content-Type": "application/json", "X-CSRF-Token": self.csrf or ""})
        try:
            with self.opener.open(req, timeout=30) as r:
                data = r.read()
                return r.status, (json.loads(data) if r.headers.get_content_type() == "application/json" else data)
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read() or b"null")

    def get(self, path):
        return self.call("GET", path)

    def post(self, path, body=None):
        return self.call("POST", path, body if body is not None else {})


def read_until(proc, pattern, timeout=120.0):
    """The first line of the process's output that matches, or fail with what it said."""
    seen = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        m = re.search(pattern, line)
        if m:
            return m
    raise AssertionError(f"no {pattern!r} in the output:\n{''.join(seen)}")


def stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture
def box(installed, tmp_path):
    """The daemon (simulated bench, the cone on the base) and the web, both from the venv."""
    data = tmp_path / "data"
    daemon = installed.start(installed.bin("inkslice"), "daemon", "--sim", "simavr", "--surface", "cone",
                             "--data", str(data))
    web = None
    try:
        read_until(daemon, r"ready: data ")
        web = installed.start(installed.bin("inkslice"), "serve", "--host", "127.0.0.1", "--port", "0",
                              "--data", str(data), "--no-usb")
        url = read_until(web, r"(http://127\.0\.0\.1:\d+)/").group(1)
        password = read_until(web, r"password: (\S+)").group(1)
        client = WebClient(url)
        client.login(password)
        yield client
    finally:
        if web is not None:
            stop(web)
        stop(daemon)


def commission(client: WebClient) -> None:
    """Once per box, from the phone: camera, level zero, tank area, meniscus from a reference ball.
    The commissioning API's steps go here, before the first scan."""


def scan(client: WebClient, params: dict, timeout: float = 600.0) -> dict:
    status, body = client.post("/api/scan", params)
    assert status == 201, body
    job_id = body["job_id"]
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        status, st = client.get("/api/state")
        assert status == 200, st
        if st["state"] in ("done", "failed") and st.get("job_id", job_id) == job_id:
            break
        time.sleep(0.5)
    status, job = client.get(f"/api/jobs/{job_id}")
    assert status == 200, job
    return job


def test_the_installed_copy_scans_on_the_simulated_bench_through_the_web(installed, box):
    client = box
    status, st = client.get("/api/state")
    assert status == 200 and st["state"] == "idle", st
    commission(client)
    job = scan(client, SCAN)
    assert job["status"] == "done", job
    assert "toolpath.gcode" in job["outputs"]
    status, gcode = client.get(f"/api/jobs/{job['id']}/files/toolpath.gcode")
    assert status == 200
    from appliance.cam.gcodeparse import parse_gcode
    program = parse_gcode(gcode.decode(), "toolpath.gcode")
    feed_z = program.xyz[program.kind == 1, 2]
    assert len(feed_z) > 100 and feed_z.max() - feed_z.min() > 5.0, "the cone's relief is milled"
    assert installed.site_files() == installed.shipped, "the simulated bench or the scan wrote into site-packages"
