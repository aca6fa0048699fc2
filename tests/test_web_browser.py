"""The web UI in headless Chromium, on a phone (390 x 844 @ 3x) and a desktop viewport.

Each run: log in, start a scan on the simulated bench, watch progress advance,
open the job's report and 3D view, download the G-code and compare it byte
for byte with the job's file, export it to a temporary "stick". Screenshots
of every page go to tests/artifacts/web/.
"""

import os
import shutil
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.needs("chromium")]

webdriver = pytest.importorskip("selenium.webdriver")
from polling import wait_until  # noqa: E402
from selenium.common.exceptions import NoSuchElementException  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from web_helpers import bench_service  # noqa: E402

from appliance.hw.usb import UsbExporter  # noqa: E402
from appliance.web.server import start  # noqa: E402

ART = Path(__file__).parent / "artifacts" / "web"
CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("box")
    media = tmp / "media"
    stick = media / "pi" / "STICK"
    stick.mkdir(parents=True)
    mounts = tmp / "mounts"
    mounts.write_text("")
    usb = UsbExporter(
        mounts_file=mounts,
        roots=(str(media),),
        sys_root=tmp / "nosys",
        unmount=lambda s: mounts.write_text(""),
    )  # what the box's stick unit does
    # 19 levels (24 -> 6 mm in 1 mm steps), each settling 0.15 s: long enough to watch progress
    svc = bench_service(tmp / "bench", settle_s=0.15, usb=usb)
    svc.update_settings({"level_step_mm": 1.0})
    run = start(svc, tmp / "data")
    ART.mkdir(parents=True, exist_ok=True)
    yield {"url": run.url, "password": run.password, "svc": svc, "mounts": mounts, "stick": stick, "tmp": tmp}
    run.stop()
    svc.close()


SIZES = {"phone": dict(width=390, height=844, ratio=3.0), "desktop": dict(width=1280, height=900, ratio=1.0)}


def chromium_options(kind, tmp):
    """Headless chromium as a phone (390 x 844 at 3x, touch) or a desktop window; one profile per kind."""
    os.environ["SE_AVOID_STATS"] = "true"
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in (
        "--headless=new",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        "--disable-gpu",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--enable-unsafe-swiftshader",
        f"--user-data-dir={tmp / ('profile-' + kind)}",
    ):
        opts.add_argument(a)
    size = SIZES[kind]
    if kind == "phone":
        opts.add_experimental_option(
            "mobileEmulation",
            {
                "deviceMetrics": {
                    "width": size["width"],
                    "height": size["height"],
                    "pixelRatio": size["ratio"],
                    "touch": True,
                },
                "userAgent": "Mozilla/5.0 (Linux; Android 14; Pixel 8) AppleWebKit/537.36 (KHTML, like Gecko) "
                "Chrome/120.0 Mobile Safari/537.36",
            },
        )
    else:
        opts.add_argument(f"--window-size={size['width']},{size['height']}")
    return opts


def make_driver(kind, tmp):
    opts = chromium_options(kind, tmp)
    downloads = tmp / f"downloads-{kind}"
    downloads.mkdir()
    opts.add_experimental_option(
        "prefs", {"download.default_directory": str(downloads), "download.prompt_for_download": False}
    )
    d = webdriver.Chrome(service=Service(DRIVER), options=opts)
    d.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
    return d, downloads


def shot(d, kind, name):
    # full page: grow the window to the document's height for the capture
    path = ART / f"{kind}-{name}.png"
    d.save_screenshot(str(path))
    assert path.stat().st_size > 5000
    return path


def wait(d, cond, timeout=20, what="the page"):
    """cond()'s first truthy value while driver `d` works; an element not on the page yet is "not yet"."""
    return wait_until(cond, timeout, what=what, every=0.05, ignoring=NoSuchElementException)


@pytest.mark.parametrize("kind", ["phone", "desktop"])
def test_scan_report_download_and_usb_in_a_browser(box, kind, tmp_path):
    d, downloads = make_driver(kind, tmp_path)
    try:
        # -- login (the dashboard sends us there first)
        d.get(box["url"] + "/")
        wait(d, lambda: "/login" in d.current_url, what="redirect to login")
        if kind == "phone":  # our pages set the viewport meta, so the layout is the phone's width
            assert d.execute_script("return [window.innerWidth, window.devicePixelRatio]") == [390, 3]
        d.find_element(By.ID, "password").send_keys("wrong password")
        d.find_element(By.ID, "login-button").click()
        wait(d, lambda: d.find_elements(By.ID, "login-error"), what="login refused")
        assert "Wrong password" in d.find_element(By.ID, "login-error").text
        shot(d, kind, "login")
        d.find_element(By.ID, "password").send_keys(box["password"])
        d.find_element(By.ID, "login-button").click()
        wait(d, lambda: d.find_elements(By.ID, "startstop"), what="dashboard")
        btn = d.find_element(By.ID, "startstop")
        wait(d, lambda: btn.is_enabled() and btn.text == "Start scan…", what="start button ready")
        if kind == "phone":
            # the big button fills the phone's width and is a comfortable thumb target
            assert btn.size["width"] >= 330 and btn.size["height"] >= 50

        # -- start (confirmed), and watch progress advance through the live stream (SSE)
        btn.click()
        wait(d, lambda: d.find_element(By.ID, "confirm").is_displayed(), what="start confirmation")
        d.find_element(By.ID, "confirm-start").click()
        wait(d, lambda: btn.text == "Stop scan", what="scan started")
        # the tab's title follows the scan (static/notify.js), so a phone in another tab sees it
        wait(d, lambda: " % · " in d.title or d.title.startswith("processing"), what="progress in the title")
        prog = d.find_element(By.ID, "progress")
        seen = []
        end = time.monotonic() + 30
        while time.monotonic() < end:
            v = int(float(prog.get_attribute("value")))
            if not seen or v != seen[-1]:
                seen.append(v)
            if len(seen) >= 4 and v > 10:
                break
            time.sleep(0.05)
        assert len(seen) >= 4 and seen == sorted(seen), seen
        assert "levels" in d.find_element(By.ID, "levels").text
        wait(d, lambda: "left" in d.find_element(By.ID, "eta").text, what="an ETA")
        wait(
            d,
            lambda: d.execute_script(
                "const i=document.getElementById('frame');return i.complete && i.naturalWidth"
            ),
            what="camera frame shown",
        )
        wait(d, lambda: "Heights" in d.find_element(By.ID, "livemap-note").text, what="growing height map")
        shot(d, kind, "dashboard-scanning")
        wait(d, lambda: d.find_element(By.ID, "state").text.lower() == "done", timeout=40, what="scan done")
        assert d.find_element(By.ID, "levels").text.startswith("19 / 19")
        job_id = box["svc"].state()["job_id"]
        shot(d, kind, "dashboard-done")

        # -- the job page: report, error picture, 3D view
        link = d.find_element(By.CSS_SELECTOR, "#job-link a")
        wait(d, lambda: link.is_displayed())
        link.click()
        wait(d, lambda: d.find_elements(By.ID, "report"), what="job page")
        assert job_id in d.find_element(By.TAG_NAME, "h1").text
        rows = {
            r.find_element(By.TAG_NAME, "summary").text: r.find_element(By.TAG_NAME, "td").text
            for r in d.find_elements(By.CSS_SELECTOR, "table.stats tr")
        }
        # the report's figures (light_processor's), its frame count among them: every level
        assert rows["Mean error"].startswith("0.0722") and rows["Cells compared"].startswith("19")
        wait(
            d,
            lambda: d.execute_script(
                "const i=document.querySelector('img.errimg');return i.complete && i.naturalWidth > 0"
            ),
            what="error picture",
        )
        canvas = d.find_element(By.ID, "view3d")
        wait(d, lambda: canvas.get_attribute("data-ready") in ("1", "error"), what="3D view")
        assert canvas.get_attribute("data-ready") == "1", d.find_element(By.ID, "view-info").text
        assert "toolpath moves" in d.find_element(By.ID, "view-info").text
        d.execute_script("arguments[0].scrollIntoView()", canvas)
        time.sleep(0.3)

        def colours():
            # count distinct colours in the WebGL canvas: a drawn mesh has many, a blank one has one
            return d.execute_script("""
                const c = document.getElementById('view3d'); const t = document.createElement('canvas');
                t.width = 64; t.height = 64; const x = t.getContext('2d'); x.drawImage(c, 0, 0, 64, 64);
                const p = x.getImageData(0, 0, 64, 64).data; const s = new Set();
                for (let i = 0; i < p.length; i += 4) s.add((p[i] >> 3) + ',' + (p[i+1] >> 3) + ',' + (p[i+2] >> 3));
                return [s.size, c.toDataURL().length];""")

        n_colours, url_len = colours()
        assert n_colours > 20, n_colours
        before = d.execute_script("return document.getElementById('view3d').toDataURL()")
        webdriver.ActionChains(d).move_to_element(canvas).click_and_hold().move_by_offset(
            60, 20
        ).release().perform()
        time.sleep(0.3)
        after = d.execute_script("return document.getElementById('view3d').toDataURL()")
        assert after != before, "dragging must turn the view"
        shot(d, kind, "job-3d")
        d.execute_script("window.scrollTo(0, 0)")
        shot(d, kind, "job-report")

        # -- download the G-code through the page's link, byte for byte
        a = d.find_element(By.CSS_SELECTOR, 'a[data-file="toolpath.gcode"]')
        d.execute_script("arguments[0].scrollIntoView()", a)
        a.click()
        target = downloads / a.get_attribute("download")  # named for the job
        assert target.name.endswith(f"-{job_id.split('-')[1]}-toolpath.gcode"), target.name
        wait(
            d, lambda: target.exists() and not list(downloads.glob("*.crdownload")), what="download finished"
        )
        assert target.read_bytes() == box["svc"].job_file(job_id, "toolpath.gcode").read_bytes()

        # -- USB: the button appears only when a stick is plugged in
        usb = d.find_element(By.ID, "usb")
        time.sleep(0.5)
        assert not usb.is_displayed()
        box["mounts"].write_text(f"/dev/sdb1 {box['stick']} vfat rw,nosuid 0 0\n")
        try:
            wait(d, lambda: usb.is_displayed(), timeout=10, what="USB section appears")
            d.execute_script("arguments[0].scrollIntoView()", usb)
            assert "STICK" in d.find_element(By.ID, "usb-stick").text
            d.find_element(By.ID, "usb-copy").click()
            wait(
                d,
                lambda: "unmounted: safe to remove" in d.find_element(By.ID, "usb-result").text,
                what="USB copy",
            )
            shot(d, kind, "job-usb")
            copied = box["stick"] / "inkslice" / f"{job_id}-toolpath.gcode"
            assert copied.read_bytes() == box["svc"].job_file(job_id, "toolpath.gcode").read_bytes()
        finally:
            box["mounts"].write_text("")
        # the copy unmounted the stick: the button goes, the outcome stays to be read
        wait(
            d,
            lambda: not d.find_element(By.ID, "usb-copy").is_displayed(),
            timeout=10,
            what="the copy button hides when the stick is gone",
        )
        assert usb.is_displayed() and "safe to remove" in d.find_element(By.ID, "usb-result").text

        # -- settings: a bad value is refused naming the key, a good one saved
        d.get(box["url"] + "/settings#group-cam")  # the group chip's link opens the CAM group
        field = d.find_element(By.NAME, "cutter_diameter_mm")
        field.clear()
        field.send_keys("-1")
        d.find_element(By.CSS_SELECTOR, "#settings-form button[type=submit]").click()
        wait(
            d,
            lambda: "must be at least 0.1" in d.find_element(By.ID, "err-cutter_diameter_mm").text,
            what="refusal beside the field",
        )
        assert "Cutter diameter" in d.find_element(By.ID, "settings-result").text
        good = 3.175 if box["svc"].settings()["cutter_diameter_mm"] != 3.175 else 4.0  # phone, then desktop
        field.clear()
        field.send_keys(str(good))
        d.find_element(By.CSS_SELECTOR, "#settings-form button[type=submit]").click()
        wait(d, lambda: d.find_element(By.ID, "settings-result").text.startswith("Saved at"), what="saved")
        assert box["svc"].settings()["cutter_diameter_mm"] == good
        shot(d, kind, "settings")

        # -- calibration: guided steps and the preview of what was detected
        d.get(box["url"] + "/calibration")
        do = d.find_element(By.ID, "cal-do")
        wait(d, lambda: do.text.startswith("Do step"), what="calibration steps")
        for _ in range(4):
            label = do.text
            do.click()
            wait(d, lambda: do.text != label, what="next step")
            if "detect" in label:
                wait(d, lambda: "corners 54" in d.find_element(By.ID, "cal-detected").text, what="detections")
                wait(
                    d,
                    lambda: d.execute_script(
                        "const i=document.getElementById('cal-frame');return i.complete && i.naturalWidth > 0"
                    ),
                )
                shot(d, kind, "calibration")
        d.get(box["url"] + "/jobs")
        assert job_id in d.find_element(By.ID, "jobs").text
        shot(d, kind, "jobs")
        d.get(box["url"] + "/api/docs")
        wait(d, lambda: len(d.find_elements(By.CSS_SELECTOR, ".api-op")) > 15, what="API docs")
        shot(d, kind, "api-docs")

        # -- no page may be wider than the phone (no sideways scrolling)
        for path in ("/", f"/jobs/{job_id}", "/settings", "/calibration", "/jobs"):
            d.get(box["url"] + path)
            time.sleep(0.2)
            sw, iw = d.execute_script("return [document.documentElement.scrollWidth, window.innerWidth]")
            assert sw <= iw, (path, sw, iw)
        # expected refusals: the wrong password (401) and the negative cutter (400); anything else
        # (a script error, a 404 asset, a CSP violation) fails the test
        expected = (
            "/login - Failed to load resource: the server responded with a status of 401",
            "/api/settings - Failed to load resource: the server responded with a status of 400",
            "favicon.ico",
        )
        errors = [
            e["message"]
            for e in d.get_log("browser")
            if e["level"] == "SEVERE" and not any(x in e["message"] for x in expected)
        ]
        assert not errors, errors
    finally:
        d.quit()
        shutil.rmtree(tmp_path / f"profile-{kind}", ignore_errors=True)
