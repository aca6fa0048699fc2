"""Shared bits for the web tests: an app on a FakeBenchService, logged-in clients."""

import re
import time

from appliance.web import create_app
from appliance.web.fake import FakeBenchService

CSRF_RE = re.compile(r'name="csrf-token" content="([^"]+)"')


def make_app(tmp_path, fast=True, **config):
    svc = FakeBenchService(
        tmp_path / "bench", level_s=0.01 if fast else 0.15, home_s=0.01, process_s=0.01, frame_px=96
    )
    cfg = {"data_dir": str(tmp_path / "data")}
    cfg.update(config)
    app = create_app(svc, cfg)
    app.config["TESTING"] = True
    return app, svc


def csrf_of(client, path="/login"):
    return CSRF_RE.search(client.get(path).get_data(as_text=True)).group(1)


def login(client, password, addr="127.0.0.1"):
    tok = csrf_of(client)
    r = client.post(
        "/login", data={"password": password, "csrf_token": tok}, environ_base={"REMOTE_ADDR": addr}
    )
    assert r.status_code == 302, r.get_data(as_text=True)
    return csrf_of(client, "/")


def wait_state(client, states, timeout=10.0, headers=None):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        st = client.get("/api/state", headers=headers or {}).get_json()
        if st["state"] in states:
            return st
        time.sleep(0.02)
    raise AssertionError(f"bench never reached {states}: {st}")
