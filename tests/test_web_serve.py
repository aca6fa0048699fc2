"""`inkslice serve --fake` as a real process (the daemon's BenchService on the in-memory bench, in
the web's process): prints the URL and the first-run password, serves over HTTP."""

import http.cookiejar
import re
import subprocess
import sys
import urllib.error
import urllib.parse
import urllib.request

import pytest
from polling import wait_until
from web_helpers import bench_service


def test_serve_prints_url_and_password_and_the_password_logs_in(tmp_path):
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
            str(tmp_path),
            "--no-usb",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        url_line = proc.stdout.readline()
        pw_line = proc.stdout.readline()
        url = re.search(r"(http://127\.0\.0\.1:\d+)/", url_line).group(1)
        password = re.search(r"password: (\S+)", pw_line).group(1)
        assert urllib.request.urlopen(url + "/api/health", timeout=5).status == 200
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(url + "/api/state", timeout=5)
        assert e.value.code == 401
        jar = http.cookiejar.CookieJar()
        opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(jar))
        page = opener.open(url + "/login", timeout=5).read().decode()
        csrf = re.search(r'name="csrf-token" content="([^"]+)"', page).group(1)
        form = urllib.parse.urlencode({"password": password, "csrf_token": csrf}).encode()
        opener.open(url + "/login", data=form, timeout=10)
        state = opener.open(url + "/api/state", timeout=5).read().decode()
        assert '"state": "idle"' in state or '"state":"idle"' in state
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    # a second start on the same data folder makes no new password
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "from appliance.web.app import create_app;"
            "from appliance.daemon.service import BenchService;"
            "from appliance.sim.fakes import FakeBench;"
            f"s=BenchService({str(tmp_path / 'x')!r},FakeBench('cone'));"
            f"a=create_app(s,{{'data_dir':{str(tmp_path)!r},'usb':None}});"
            "print(a.config['FIRST_RUN_PASSWORD']);s.close()",
        ],
        capture_output=True,
        text=True,
    )
    assert out.stdout.strip() == "None", out.stderr


def test_a_closed_live_stream_frees_its_slot_under_waitress(tmp_path):
    import http.client

    from appliance.web.auth import Credentials
    from appliance.web.server import start

    svc = bench_service(tmp_path / "bench")
    run = start(svc, tmp_path / "data", config={"usb": None, "max_streams": 1})
    token = Credentials(tmp_path / "data" / "web").create_token("t")[1]
    port = int(run.url.rsplit(":", 1)[1])

    def open_stream():
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        c.request("GET", "/api/events", headers={"Authorization": f"Bearer {token}"})
        return c, c.getresponse()

    try:
        c1, r1 = open_stream()
        assert r1.status == 200 and r1.readline().startswith(b"retry:")
        c2, r2 = open_stream()
        assert r2.status == 503  # the one slot is taken
        c2.close()
        r1.close()
        c1.close()  # the phone goes away mid-stream

        def slot_back():
            c3, r3 = open_stream()
            if r3.status == 200:
                return c3
            c3.close()
            return None

        # the slot of a closed stream comes back within seconds, not at 50 s
        wait_until(slot_back, 5, what="the closed stream's slot", every=0.2).close()
    finally:
        run.stop()
        svc.close()
