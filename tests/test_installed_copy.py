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
    firmware under simavr, the virtual camera with the physics effects: the
    ink's displacement and its meniscus) and the web. A client logs in and
    scans dissertation sample 3 on the new box: the report warns that no
    meniscus, tank, camera or level-zero calibration was used. It then
    commissions the box through the web API as the phone's page does
    (commission(), below) and scans the part again: the G-code comes out and
    the height map is within Ea 0.03 mm of the true surface, the figure
    `benches/seed_table.py --effects physics` reaches.

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
from polling import wait_until

REPO = Path(__file__).resolve().parents[1]
pytestmark = [
    pytest.mark.slow,
    pytest.mark.simavr,
    pytest.mark.needs("simavr"),
]


@dataclass
class Installed:
    wheel: Path
    venv: Path
    site: Path  # the venv's site-packages, where the wheel went
    run_dir: Path  # the working folder of every process (not the checkout)
    env: dict
    shipped: list = None  # site_files() right after the install

    def site_files(self) -> list[Path]:
        """What the wheel put into site-packages (byte-code caches aside): nothing may add to it."""
        return sorted(p for p in (self.site / "appliance").rglob("*") if "__pycache__" not in p.parts)

    def bin(self, name: str) -> str:
        return str(self.venv / "bin" / name)

    def run(self, *args, **kw) -> subprocess.CompletedProcess:
        return subprocess.run(
            list(args),
            cwd=self.run_dir,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=kw.pop("timeout", 300),
            **kw,
        )

    def start(self, *args) -> subprocess.Popen:
        return subprocess.Popen(
            list(args),
            cwd=self.run_dir,
            env=self.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )


def laid_out(root: Path) -> Path:
    """The sources as `systemd/install.sh` copies them to the box (/opt/inkslice under root)."""
    r = subprocess.run(
        [str(REPO / "systemd/install.sh"), "--root", str(root)], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    return root / "opt" / "inkslice"


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Installed:
    tmp = tmp_path_factory.mktemp("installed")
    src = laid_out(tmp / "root")
    wheel_dir = tmp / "dist"
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheel_dir), str(src)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    (wheel,) = wheel_dir.glob("inkslice-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    (site / "shared-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    r = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", str(wheel)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    shutil.rmtree(tmp / "root")  # nothing of the sources is left to fall back on
    run_dir = tmp / "run"
    run_dir.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "INKSLICE_", "VIRTUAL_ENV"))}
    env.update(
        PATH=f"{venv / 'bin'}:{env.get('PATH', '/usr/bin:/bin')}",
        XDG_CACHE_HOME=str(tmp / "cache"),
        PYTHONUNBUFFERED="1",
    )
    box = Installed(wheel, venv, site, run_dir, env)
    box.shipped = box.site_files()
    return box


def test_the_installed_copy_imports_from_its_own_venv_and_reads_the_protocol_table(installed):
    r = installed.run(
        installed.bin("python"),
        "-c",
        """if True:
        import json, os, sys
        import appliance, appliance.hw.protocol as P
        from appliance.firmware import codes_path
        print(json.dumps({"appliance": appliance.__file__, "cwd": os.getcwd(), "path": sys.path,
                          "codes": str(codes_path()), "settings": len(P.SETTINGS),
                          "verbs": list(P.VERBS), "line_max": P.LINE_MAX}))""",
    )
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    assert Path(got["appliance"]).is_relative_to(installed.site)
    assert Path(got["codes"]).is_relative_to(installed.site) and Path(got["codes"]).name == "codes.def"
    assert got["settings"] > 0 and "MOVE" in got["verbs"] and got["line_max"] > 0
    assert not Path(got["cwd"]).is_relative_to(REPO)
    # the one path into the checkout allowed is the shared dependencies' site-packages (in CI the
    # test venv lives in the checkout): it holds numpy and friends, never a copy of `appliance`
    deps = Path(sysconfig.get_paths()["purelib"]).resolve()
    assert not (deps / "appliance").exists()
    assert not [
        p for p in got["path"] if p and Path(p).resolve().is_relative_to(REPO) and Path(p).resolve() != deps
    ]


def test_the_wheel_holds_the_modules_of_the_checkout_and_what_they_need_at_run_time(installed):
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    tracked = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "appliance"],
        cwd=REPO,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    # every module, and nothing else (a stale build/ folder would add deleted ones)
    assert {n for n in names if n.endswith(".py")} == {n for n in tracked if n.endswith(".py")}
    fw = "appliance/firmware/stepper/"
    needed = {
        fw + "codes.def",
        fw + "Makefile",
        fw + "sim/hil.c",
        "appliance/web/static/chessboard.pdf",
        "appliance/web/static/chessboard.png",
    }
    needed |= {
        n for n in tracked if n.startswith((fw + "src/", "appliance/web/templates/", "appliance/web/static/"))
    }
    assert needed <= names, sorted(needed - names)
    assert not [n for n in names if "/build/" in n or n.endswith((".o", ".elf", ".hex"))], (
        "build outputs shipped"
    )


def test_the_installed_copy_builds_and_flashes_the_firmware(installed, tmp_path):
    """`inkslice firmware flash` builds the HEX into the cache and runs avrdude on it. avrdude
    itself is stood in for by a script that records what it was given (no board here)."""
    fake_bin = tmp_path / "bin"
    fake_bin.mkdir()
    record = tmp_path / "avrdude.json"
    (fake_bin / "avrdude").write_text(
        f"#!{sys.executable}\nimport json, sys\njson.dump(sys.argv[1:], open({str(record)!r}, 'w'))\n"
    )
    (fake_bin / "avrdude").chmod(0o755)
    env = {**installed.env, "PATH": f"{fake_bin}:{installed.env['PATH']}"}
    r = subprocess.run(
        [installed.bin("inkslice"), "firmware", "flash", "--port", "/dev/ttyACM7"],
        cwd=installed.run_dir,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "flashed /dev/ttyACM7" in r.stdout
    args = json.loads(record.read_text())
    assert args[:8] == ["-p", "m328p", "-c", "arduino", "-P", "/dev/ttyACM7", "-b", "115200"]
    hex_file = Path(re.fullmatch(r"flash:w:(.+):i", args[-1]).group(1))
    assert hex_file.is_relative_to(Path(installed.env["XDG_CACHE_HOME"]))
    lines = hex_file.read_text().splitlines()
    assert lines[0].startswith(":") and lines[-1] == ":00000001FF" and len(lines) > 100  # Intel HEX
    assert installed.site_files() == installed.shipped, "the build wrote into site-packages"


# ---- both services from the installed copy -------------------------------------------------------


class WebClient:
    """A browser's worth of HTTP: a cookie jar, the CSRF token, JSON in and out."""

    def __init__(self, url):
        self.url = url
        self.opener = urllib.request.build_opener(
            urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar())
        )
        self.csrf = None

    def _csrf_of(self, path):
        page = self.opener.open(self.url + path, timeout=10).read().decode()
        return re.search(r'name="csrf-token" content="([^"]+)"', page).group(1)

    def login(self, password):
        form = urllib.parse.urlencode({"password": password, "csrf_token": self._csrf_of("/login")}).encode()
        self.opener.open(self.url + "/login", data=form, timeout=10)
        self.csrf = self._csrf_of("/")

    def call(self, method, path, body=None, timeout=30.0):
        req = urllib.request.Request(
            self.url + path,
            method=method,
            data=None if body is None else json.dumps(body).encode(),
            headers={"Content-Type": "application/json", "X-CSRF-Token": self.csrf or ""},
        )
        try:
            with self.opener.open(req, timeout=timeout) as r:
                data = r.read()
                return r.status, (
                    json.loads(data) if r.headers.get_content_type() == "application/json" else data
                )
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read() or b"null")

    def get(self, path):
        return self.call("GET", path)

    def post(self, path, body=None, timeout=30.0):
        return self.call("POST", path, body if body is not None else {}, timeout)

    def file(self, job_id, name):
        status, data = self.get(f"/api/jobs/{job_id}/files/{name}")
        assert status == 200, (name, data)
        return data


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


# The bench: dissertation sample 3 (a 100 x 100 mm Bezier patch, 28.7 .. 49.8 mm high) in ink with
# the physics effects (displacement in a 150 x 150 mm tank, a meniscus of 2.7 mm capillary length),
# and the stage's true level zero where the daemon's setting (60 mm) does not expect it.
#
# The frame is 1024 x 768, not the bench's 2048 x 1536: the smallest tried that still gives
# Ea <= 0.03 mm on sample 3 through the daemon. Measured with the daemon's service in-process
# on this bench, commissioned the same way, levels 1 mm apart from 50 mm down (2 busy shared cores):
#   2048 x 1536: Ea 0.0234 mm; commissioning 173 s, the scan with processing and CAM 173 s
#   1024 x  768: Ea 0.0250 mm; commissioning  71 s, the scan with processing and CAM 113 s
#    640 x  480: Ea 0.0318 mm (misses);        71 s,                                  99 s
# (the first two down to 20 mm, the last to 24 mm as here). This test itself measures Ea 0.0244 mm.
# Below 1024 x 768 little time is left to save: processing and the CAM take most of a scan.
FRAME = "1024x768"
TRUE_LEVEL_ZERO = 57.3
# the dissertation's levels for sample 3 (benches/seed_table.py's sculpture_levels): from just
# above its top down until the top's lowest point (28.7 mm) is a meniscus rise clear of the ink
SAMPLE3 = {"levels_to_mm": 50.0, "levels_from_mm": 24.0, "level_step_mm": 1.0, "settle_s": 0.0}
BENCH_EA_MM = 0.03  # what benches/seed_table.py --effects physics reaches on sample 3 (0.0238)
COMMISSION_TIMEOUT = 600.0  # an action on the bench (the level-zero search) answers when it is done


@pytest.fixture(scope="module")
def box(installed, tmp_path_factory):
    """The daemon (the simulated bench above) and the web, both from the venv, a client logged in."""
    data = tmp_path_factory.mktemp("box") / "data"
    daemon = installed.start(
        installed.bin("inkslice"),
        "daemon",
        "--sim",
        "simavr",
        "--surface",
        "sample3",
        "--frame",
        FRAME,
        "--effects",
        "physics",
        "--level-zero",
        str(TRUE_LEVEL_ZERO),
        "--data",
        str(data),
    )
    web = None
    try:
        read_until(daemon, r"ready: data ")
        web = installed.start(
            installed.bin("inkslice"),
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--data",
            str(data),
            "--no-usb",
        )
        url = read_until(web, r"(http://127\.0\.0\.1:\d+)/").group(1)
        password = read_until(web, r"password: (\S+)").group(1)
        client = WebClient(url)
        client.login(password)
        yield client
    finally:
        if web is not None:
            stop(web)
        stop(daemon)


def act(client: WebClient, step: str, action: str, values: dict | None = None) -> dict:
    """One button on the commissioning page."""
    status, c = client.post(f"/api/commissioning/{step}/{action}", values or {}, timeout=COMMISSION_TIMEOUT)
    assert status == 200, (step, action, c)
    return c


def commission(client: WebClient) -> dict:
    """Once per box, from the phone, in the page's order and with what the page sends: level zero
    measured, the camera from three tilted views of the board and the board flat on the base, the
    tank entered (150 x 150 mm), the meniscus from a scan of the 25.4 mm reference ball."""
    act(client, "level_zero", "start")
    c = act(client, "level_zero", "measure")
    assert c["active"]["stage"] == "check", c["active"]
    act(client, "level_zero", "accept")
    act(client, "camera", "start")
    for n in (1, 2, 3):
        c = act(client, "camera", "view")
        assert c["active"]["detected"]["views"] == n, c["active"]
    act(client, "camera", "plane")
    act(client, "camera", "accept")
    act(client, "tank", "enter", {"width_mm": 150, "depth_mm": 150})
    act(client, "meniscus", "start", {"diameter_mm": 25.4})
    c = act(client, "meniscus", "scan")
    assert c["active"]["stage"] == "scanning", c["active"]

    def scanned():  # the page polls the same way
        status, c = client.get("/api/commissioning")
        assert status == 200, c
        return c if c["active"]["stage"] != "scanning" else None

    c = wait_until(scanned, COMMISSION_TIMEOUT, what="the meniscus scan", every=1.0)
    assert c["active"]["stage"] == "check", c["active"]
    return act(client, "meniscus", "accept")


def scan(client: WebClient, params: dict, timeout: float = 900.0) -> dict:
    status, body = client.post("/api/scan", params)
    assert status == 201, body
    job_id = body["job_id"]

    def ended():
        status, st = client.get("/api/state")
        assert status == 200, st
        return st["state"] in ("done", "failed") and st.get("job_id", job_id) == job_id

    wait_until(ended, timeout, what=f"job {job_id} to end", every=0.5)
    status, job = client.get(f"/api/jobs/{job_id}")
    assert status == 200, job
    return job


def height_map_error(client: WebClient, job: dict, tmp_path: Path) -> dict:
    """The job's heightmap.csv, as the web hands it out, against sample 3's true surface."""
    from appliance.outputs import read_heightmap_csv
    from appliance.process import statistics_against
    from appliance.sim import surfaces

    path = tmp_path / f"{job['id']}-heightmap.csv"
    path.write_bytes(client.file(job["id"], "heightmap.csv"))
    return statistics_against(surfaces.get("sample3"), read_heightmap_csv(path))


@pytest.fixture(scope="module")
def scans(installed, box, tmp_path_factory):
    """A new box's story: a scan before commissioning, the commissioning, the same part again."""
    client = box
    status, st = client.get("/api/state")
    assert status == 200 and st["state"] == "idle", st
    # this scan is about its report: a coarse scallop keeps the finishing program short (its height
    # map, level zero unmeasured, is ~3 mm off and rough; at 0.05 mm the CAM took 4.5 minutes)
    before = scan(client, {**SAMPLE3, "name": "sample 3, not commissioned", "scallop_mm": 0.5})
    commissioned = commission(client)
    after = scan(client, {**SAMPLE3, "name": "sample 3, commissioned"})
    return {
        "client": client,
        "before": before,
        "commissioning": commissioned,
        "after": after,
        "tmp": tmp_path_factory.mktemp("downloads"),
    }


def test_before_commissioning_the_report_warns_that_no_meniscus_or_tank_calibration_was_used(scans):
    client, job = scans["client"], scans["before"]
    assert job["status"] == "done", job
    report = client.file(job["id"], "report.json")
    warnings = " | ".join(report["calibration"]["warnings"])
    for expected in (
        "no meniscus calibration was used",
        "no tank area calibration was used",
        "the camera was not commissioned",
        "level zero was not measured",
    ):
        assert expected in warnings, warnings
    md = client.file(job["id"], "report.md").decode()
    assert "no meniscus calibration was used" in md and "no tank area calibration was used" in md


def test_the_commissioning_through_the_web_measures_the_box(scans):
    c = scans["commissioning"]
    steps = {s["id"]: s for s in c["steps"]}
    assert c["active"] is None
    assert {k: s["status"] for k, s in steps.items()} == dict.fromkeys(
        ("level_zero", "camera", "tank", "meniscus"), "done"
    )
    assert abs(steps["level_zero"]["result"]["level_at_home_mm"] - TRUE_LEVEL_ZERO) <= 0.01
    assert steps["camera"]["result"]["plane_rms_mm"] < 0.1
    assert steps["tank"]["result"]["area_mm2"] == 22500.0
    men = steps["meniscus"]["result"]
    # the physics preset's ink: capillary length 2.7 mm, contact angle 0
    assert abs(men["capillary_length_mm"] - 2.7) < 0.2 and abs(men["contact_angle_deg"]) < 5.0, men
    assert men["reference"]["mean_abs_error_mm"] < 0.1, men["reference"]


def test_the_commissioned_installed_copy_scans_sample_3_as_accurately_as_the_bench(installed, scans):
    client, job = scans["client"], scans["after"]
    assert job["status"] == "done", job
    report = client.file(job["id"], "report.json")
    assert report["calibration"]["warnings"] == [], report["calibration"]
    used = report["calibration"]["used"]
    assert used["tank"].startswith("tank area 22500 mm² (entered, ")
    assert "the 25.4 mm ball measured to" in used["meniscus"] and used["camera"].startswith(
        "commissioned camera"
    )
    assert used["level_zero"].startswith("level zero at stage position 57.30")
    assert report["diagnostics"]["corrections"] == {"displacement_tank_area_mm2": 22500.0, "meniscus": True}
    err = height_map_error(client, job, scans["tmp"])
    assert err["Ea"] <= BENCH_EA_MM, err
    from appliance.cam.gcodeparse import parse_gcode

    program = parse_gcode(client.file(job["id"], "toolpath.gcode").decode(), "toolpath.gcode")
    feed_z = program.xyz[program.kind == 1, 2]
    assert len(feed_z) > 100 and feed_z.max() - feed_z.min() > 15.0, "sample 3's relief (21 mm) is milled"
    assert installed.site_files() == installed.shipped, (
        "the simulated bench or the scan wrote into site-packages"
    )
