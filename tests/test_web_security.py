"""Access control of the web UI: login, CSRF, tokens, rate limit, traversal, uploads."""

import io
import json
import os
import stat
import zipfile

import pytest
from web_helpers import csrf_of, login, make_app, wait_job, wait_state

UNSAFE = {"POST", "PUT", "PATCH", "DELETE"}
SAMPLE = {
    "job_id": "20260101-000000-abcd",
    "name": "toolpath.gcode",
    "step": "home",
    "token_id": "0123abcd",
    "action": "start",
}


@pytest.fixture
def env(tmp_path):
    app, svc = make_app(tmp_path)
    yield app, svc, app.config["FIRST_RUN_PASSWORD"]
    svc.close()


def unsafe_routes(app):
    out = []
    for rule in app.url_map.iter_rules():
        for m in sorted(rule.methods & UNSAFE):
            url = rule.rule
            for arg in rule.arguments:
                url = url.replace(f"<{arg}>", SAMPLE[arg])
            out.append((m, url, rule.endpoint))
    return out


def test_the_app_has_the_state_changing_routes_we_think(env):
    app, _, _ = env
    got = {(m, e) for m, _, e in unsafe_routes(app)}
    for want in [
        ("POST", "api.start_scan"),
        ("POST", "api.cancel_scan"),
        ("PATCH", "api.patch_settings"),
        ("POST", "jobs.usb_export"),
        ("POST", "uploads.upload_scan"),
        ("DELETE", "account.revoke_token"),
        ("POST", "api.calibrate"),
        ("POST", "api.commission"),
        ("POST", "api.commissioning_import"),
        ("POST", "api.commissioning_ink_changed"),
        ("POST", "pages.login"),
        ("POST", "pages.logout"),
    ]:
        assert want in got


def test_every_state_changing_route_refuses_without_session_or_token(env):
    app, svc, _ = env
    c = app.test_client()
    for method, url, endpoint in unsafe_routes(app):
        if endpoint == "pages.login":
            continue  # public by nature; its CSRF check is tested below
        r = c.open(url, method=method, json={})
        assert r.status_code == 401, (method, url, r.status_code)
    assert svc.state()["state"] == "idle"  # nothing was started


def test_every_state_changing_route_refuses_a_session_without_csrf(env):
    app, svc, pw = env
    c = app.test_client()
    good = login(c, pw)
    for method, url, _endpoint in unsafe_routes(app):
        for headers in ({}, {"X-CSRF-Token": "wrong-" + good}):
            r = c.open(url, method=method, json={}, headers=headers)
            assert r.status_code == 403, (method, url, headers, r.status_code)
    assert svc.state()["state"] == "idle"
    # and the same session with the token is let through
    assert c.post("/api/scan", json={}, headers={"X-CSRF-Token": good}).status_code == 201
    wait_state(c, {"done"})


def test_login_form_itself_needs_csrf(env):
    app, _, pw = env
    c = app.test_client()
    r = c.post("/login", data={"password": pw})
    assert r.status_code == 403
    assert c.get("/api/state").status_code == 401


def test_bearer_token_works_without_csrf_and_revoked_or_bogus_tokens_do_not(env):
    app, svc, pw = env
    c = app.test_client()
    csrf = login(c, pw)
    r = c.post("/api/tokens", json={"name": "ci script"}, headers={"X-CSRF-Token": csrf})
    assert r.status_code == 201
    token, tid = r.get_json()["token"], r.get_json()["id"]
    s = app.test_client()  # no cookies at all
    auth = {"Authorization": f"Bearer {token}"}
    assert s.get("/api/state", headers=auth).status_code == 200
    assert s.post("/api/scan", json={}, headers=auth).status_code == 201
    wait_state(s, {"done"}, headers=auth)
    # the stored file has only a hash of the token
    stored = (app.extensions["inkslice"]["creds"].tokens_file).read_text()
    assert token not in stored and token[4:] not in stored
    assert s.get("/api/state", headers={"Authorization": "Bearer isk_not-a-real-token"}).status_code == 401
    assert c.delete(f"/api/tokens/{tid}", headers={"X-CSRF-Token": csrf}).status_code == 200
    assert s.get("/api/state", headers=auth).status_code == 401
    # a token cannot mint tokens or change the password (those need a person at a browser)
    r2 = c.post("/api/tokens", json={"name": "b"}, headers={"X-CSRF-Token": csrf}).get_json()["token"]
    assert s.post("/api/tokens", json={}, headers={"Authorization": f"Bearer {r2}"}).status_code == 403
    assert (
        s.post(
            "/api/password", json={"current": pw, "new": "x" * 12}, headers={"Authorization": f"Bearer {r2}"}
        ).status_code
        == 403
    )


def test_camera_and_live_stream_are_behind_the_login(env):
    app, svc, pw = env
    c = app.test_client()
    for path in (
        "/api/frame.jpg",
        "/api/events",
        "/api/state",
        "/api/heightmap/live",
        "/api/jobs",
        "/api/settings",
    ):
        assert c.get(path).status_code == 401, path
    assert c.get("/").status_code == 302 and "/login" in c.get("/").headers["Location"]
    login(c, pw)
    assert c.get("/api/frame.jpg").status_code == 204  # logged in, but no frame yet
    # public: login page, health, the API description
    anon = app.test_client()
    for path in ("/login", "/api/health", "/api/openapi.json", "/static/app.css"):
        assert anon.get(path).status_code == 200, path


def test_login_is_rate_limited_per_address(env):
    app, _, pw = env
    c = app.test_client()
    for i in range(5):
        tok = csrf_of(c)
        r = c.post(
            "/login",
            data={"password": f"guess{i}", "csrf_token": tok},
            environ_base={"REMOTE_ADDR": "10.9.9.9"},
        )
        assert r.status_code == 401
    tok = csrf_of(c)
    r = c.post("/login", data={"password": pw, "csrf_token": tok}, environ_base={"REMOTE_ADDR": "10.9.9.9"})
    assert r.status_code == 429, "the right password must not get through while locked out"
    assert int(r.headers["Retry-After"]) > 0
    assert c.get("/api/state").status_code == 401
    other = app.test_client()
    login(other, pw, addr="10.9.9.10")  # another address is not locked out
    assert other.get("/api/state").status_code == 200


def test_limiter_window_expires():
    from appliance.web.auth import LoginLimiter

    now = [0.0]
    lim = LoginLimiter(attempts=3, window_s=60, clock=lambda: now[0])
    for _ in range(3):
        assert lim.retry_after("a") == 0
        lim.failed("a")
    assert 59 <= lim.retry_after("a") <= 60
    now[0] = 30
    assert 29 <= lim.retry_after("a") <= 31
    now[0] = 61
    assert lim.retry_after("a") == 0


def test_password_storage_and_cookie_flags(tmp_path):
    app, svc = make_app(tmp_path)
    pw = app.config["FIRST_RUN_PASSWORD"]
    web = tmp_path / "data" / "web"
    for name in ("admin.json", "secret_key"):
        assert stat.S_IMODE(os.stat(web / name).st_mode) == 0o600, name
    doc = json.loads((web / "admin.json").read_text())
    assert pw not in json.dumps(doc) and doc["hash"].startswith("scrypt:")
    assert stat.S_IMODE(os.stat(web).st_mode) == 0o700
    c = app.test_client()
    r = c.get("/login")
    cookie = r.headers["Set-Cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Secure" not in cookie
    # a second app on the same data dir keeps the password and makes no new one
    app2, svc2 = make_app(tmp_path)
    assert app2.config["FIRST_RUN_PASSWORD"] is None
    login(app2.test_client(), pw)
    # the demo's reset: a new printed password, the old one and its sessions are over
    c2 = app2.test_client()
    login(c2, pw, addr="127.0.0.9")
    app4, svc4 = make_app(tmp_path, reset_password=True)
    new = app4.config["FIRST_RUN_PASSWORD"]
    assert new and new != pw
    assert c2.get("/api/state").status_code == 401
    login(app4.test_client(), new, addr="127.0.0.10")
    svc4.close()
    app3, svc3 = make_app(tmp_path / "https", https=True)
    assert "Secure" in app3.test_client().get("/login").headers["Set-Cookie"]
    for s in (svc, svc2, svc3):
        s.close()


def test_password_change_logs_out_other_sessions(env):
    app, _, pw = env
    a, b = app.test_client(), app.test_client()
    ca = login(a, pw)
    login(b, pw, addr="127.0.0.2")
    assert (
        a.post(
            "/api/password",
            json={"current": "nope-nope", "new": "a-new-password"},
            headers={"X-CSRF-Token": ca},
        ).status_code
        == 403
    )
    assert (
        a.post(
            "/api/password", json={"current": pw, "new": "short"}, headers={"X-CSRF-Token": ca}
        ).status_code
        == 400
    )
    assert (
        a.post(
            "/api/password", json={"current": pw, "new": "a-new-password"}, headers={"X-CSRF-Token": ca}
        ).status_code
        == 200
    )
    assert a.get("/api/state").status_code == 200
    assert b.get("/api/state").status_code == 401
    fresh = app.test_client()
    tok = csrf_of(fresh)
    assert fresh.post("/login", data={"password": pw, "csrf_token": tok}).status_code == 401
    login(fresh, "a-new-password", addr="127.0.0.3")


def test_login_never_redirects_off_the_box(env):
    app, _, pw = env
    for target in ("https://evil.example/", "//evil.example/x", "javascript:alert(1)"):
        c = app.test_client()
        tok = csrf_of(c)
        r = c.post("/login", data={"password": pw, "csrf_token": tok, "next": target})
        assert r.status_code == 302 and r.headers["Location"] in ("/", "http://localhost/"), target


TRAVERSALS = [
    "../../../../etc/passwd",
    "..%2f..%2f..%2fsecret.txt",
    "..",
    "%2e%2e",
    "..%5csecret.txt",
    ".hidden",
    "a/../../secret.txt",
    "%2e%2e%2f%2e%2e%2fsecret.txt",
]


def test_dot_dot_in_any_path_parameter_is_refused(env, tmp_path):
    app, svc, pw = env
    c = app.test_client()
    csrf = login(c, pw)
    c.post("/api/scan", json={}, headers={"X-CSRF-Token": csrf})
    job_id = wait_state(c, {"done"})["job_id"]
    secret = "TOP-SECRET-CONTENT"
    (tmp_path / "bench" / "secret.txt").write_text(secret)
    (tmp_path / "bench" / "jobs" / "secret.txt").write_text(secret)
    urls = []
    for bad in TRAVERSALS:
        urls += [
            f"/api/jobs/{job_id}/files/{bad}",
            f"/api/jobs/{bad}",
            f"/api/jobs/{bad}/files/toolpath.gcode",
            f"/api/jobs/{bad}/archive.zip",
            f"/jobs/{bad}",
            f"/static/{bad}",
        ]
    for url in urls:
        r = c.get(url)
        assert r.status_code in (400, 404), (url, r.status_code)
        assert secret.encode() not in r.data and b"root:" not in r.data, url
    for bad in TRAVERSALS:
        for method, url in (
            ("POST", f"/api/jobs/{bad}/resume"),
            ("POST", f"/api/jobs/{bad}/usb"),
            ("POST", f"/api/calibration/{bad}"),
            ("DELETE", f"/api/tokens/{bad}"),
        ):
            r = c.open(url, method=method, json={}, headers={"X-CSRF-Token": csrf})
            assert r.status_code in (400, 404, 405), (method, url, r.status_code)
    # the USB export's file name goes through the same checks
    r = c.post(f"/api/jobs/{job_id}/usb", json={"file": "../secret.txt"}, headers={"X-CSRF-Token": csrf})
    assert r.status_code == 400


# -- uploads -------------------------------------------------------------------------------


def png_header(width, height):
    """A PNG's signature and IHDR: all the web reads of a frame before unpacking it."""
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + struct.pack(">I", 13)
        + b"IHDR"
        + ihdr
        + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    )


def scan_zip(frames=2, prefix="", extra=None, scan=None):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        doc = scan or {
            "format": "inkslice.scan/1",
            "units": "mm",
            "camera": {"width": 4, "height": 4, "homography": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
            "frames": [{"file": f"frames/{i:04d}.png", "level_mm": i * 0.5} for i in range(frames)],
        }
        z.writestr(prefix + "scan.json", json.dumps(doc))
        for i in range(frames):
            z.writestr(f"{prefix}frames/{i:04d}.png", png_header(4, 4))
        for name, data in (extra or {}).items():
            z.writestr(name, data)
    return buf.getvalue()


def uploads_left(tmp_path):
    d = tmp_path / "data" / "web" / "uploads"
    return sorted(p.name for p in d.iterdir()) if d.exists() else []


def test_uploads_valid_ones_become_jobs(tmp_path):
    app, svc = make_app(tmp_path, max_upload_bytes=64 * 1024, max_unzipped_bytes=256 * 1024)
    c = app.test_client()
    csrf = login(c, app.config["FIRST_RUN_PASSWORD"])
    r = c.post(
        "/api/uploads/scan",
        data={"file": (io.BytesIO(scan_zip(prefix="myscan/")), "scan.zip")},
        headers={"X-CSRF-Token": csrf},
        content_type="multipart/form-data",
    )
    assert r.status_code == 201, r.get_json()
    job_id = r.get_json()["job_id"]
    assert wait_job(svc, job_id)["status"] == "done"
    # the service keeps its own copy of the scan; the web's unpacked upload is gone
    assert uploads_left(tmp_path) == []
    assert svc.job_file(job_id, "scan/frames/0001.png").is_file()
    svc.close()


@pytest.mark.parametrize(
    "case",
    [
        "oversized",
        "not-a-zip",
        "truncated",
        "dotdot",
        "absolute",
        "bomb",
        "no-scan-json",
        "bad-json",
        "missing-frame",
        "symlink",
    ],
)
def test_uploads_bad_ones_are_refused_and_leave_nothing(tmp_path, case):
    app, svc = make_app(tmp_path, max_upload_bytes=64 * 1024, max_unzipped_bytes=256 * 1024)
    c = app.test_client()
    csrf = login(c, app.config["FIRST_RUN_PASSWORD"])
    good = scan_zip()
    if case == "oversized":
        body, want = os.urandom(80 * 1024), 413
    elif case == "not-a-zip":
        body, want = b"this is not a zip at all" * 10, 400
    elif case == "truncated":
        body, want = good[: len(good) // 2], 400
    elif case == "dotdot":
        body, want = scan_zip(extra={"../../escape.txt": b"x"}), 400
    elif case == "absolute":
        body, want = scan_zip(extra={"/tmp/abs.txt": b"x"}), 400
    elif case == "bomb":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("scan.json", json.dumps({"frames": [{"file": "frames/0000.png", "level_mm": 0}]}))
            z.writestr("frames/0000.png", b"\0" * (2 * 1024 * 1024))  # 2 MiB of zeros packs to ~2 KB
        body, want = buf.getvalue(), 400
        assert len(body) < 64 * 1024
    elif case == "no-scan-json":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z:
            z.writestr("frames/0000.png", b"x")
        body, want = buf.getvalue(), 400
    elif case == "bad-json":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z:
            z.writestr("scan.json", b"{not json")
        body, want = buf.getvalue(), 400
    elif case == "missing-frame":
        doc = json.loads(zipfile.ZipFile(io.BytesIO(good)).read("scan.json"))
        doc["frames"][1]["file"] = "frames/9999.png"
        body, want = scan_zip(scan=doc), 400
    elif case == "symlink":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z:
            z.writestr("scan.json", json.dumps({"frames": [{"file": "f.png", "level_mm": 0}]}))
            info = zipfile.ZipInfo("f.png")
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            z.writestr(info, "/etc/passwd")
        body, want = buf.getvalue(), 400
    jobs_before = len(svc.jobs())
    r = c.post(
        "/api/uploads/scan",
        data={"file": (io.BytesIO(body), "scan.zip")},
        headers={"X-CSRF-Token": csrf},
        content_type="multipart/form-data",
    )
    assert r.status_code == want, (case, r.status_code, r.get_data(as_text=True))
    assert "error" in r.get_json()
    assert uploads_left(tmp_path) == [], case
    assert len(svc.jobs()) == jobs_before
    assert not (tmp_path / "escape.txt").exists() and not os.path.exists("/tmp/abs.txt")
    # raw application/zip bodies go through the same checks
    r = c.post("/api/uploads/scan", data=body, headers={"X-CSRF-Token": csrf}, content_type="application/zip")
    assert r.status_code == want
    assert uploads_left(tmp_path) == []
    svc.close()


def test_security_headers(env):
    app, _, pw = env
    c = app.test_client()
    login(c, pw)
    r = c.get("/")
    csp = r.headers["Content-Security-Policy"]
    assert "default-src 'self'" in csp and "frame-ancestors 'none'" in csp and "unsafe-inline" not in csp
    assert r.headers["X-Frame-Options"] == "DENY"
    assert c.get("/api/state").headers["Cache-Control"] == "no-store"
