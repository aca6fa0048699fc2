"""Every screen, at both sizes: the web UI in headless Chromium on a phone (390 x 844 at 3x) and a
desktop (1280 x 900), on the daemon's real BenchService driving the in-memory bench (sim.fakes).

Each screen in SCREENS is opened, made ready (its data loaded), screenshotted in full to
tests/artifacts/web/screen-<size>-<name>.png, and must have:
  - no horizontal overflow (nothing wider than the window);
  - every control at least 44 x 44 CSS px (a checkbox through its label; a link inside a sentence
    is exempt, as WCAG 2.5.8 exempts inline targets);
  - a label on every control (a <label>, aria-label(ledby) or title; a button's or link's text);
  - no console error;
  - no serious or critical violation found by axe-core (installed from npm into tests/a11y by
    scripts/setup.sh --test, run inside the same page).
All screens are checked before the test fails, so one run lists every fault of every screen.

A new screen is one more Screen(...) in SCREENS: a name, its path, and what "ready" means.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.needs("chromium", "axe-core")]

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.common.exceptions import TimeoutException, WebDriverException  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from test_web_browser import SIZES, chromium_options, wait  # noqa: E402
from test_web_real_service import light_processor  # noqa: E402

from appliance.daemon.service import BenchService  # noqa: E402
from appliance.sim.fakes import FakeBench  # noqa: E402
from appliance.web.server import start  # noqa: E402

HERE = Path(__file__).parent
ART = HERE / "artifacts" / "web"
AXE = HERE / "a11y" / "node_modules" / "axe-core" / "axe.min.js"
CHECKS = (HERE / "screen_checks.js").read_text()
CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
# a scan slow enough to be seen scanning (settle_s per level), quick enough for a test
SCAN = {
    "name": "cone on the bench",
    "surface": "cone",
    "levels_to_mm": 24.0,
    "levels_from_mm": 6.0,
    "level_step_mm": 2.0,
    "settle_s": 0.5,
}


def loaded_img(d, css):
    return d.execute_script(
        f"const i=document.querySelector({json.dumps(css)});return !!i && i.complete && i.naturalWidth > 0"
    )


def state_of(box):
    return box["svc"].state()["state"]


# -- the screens -------------------------------------------------------------------------------


@dataclass
class Screen:
    name: str
    path: Callable[[dict], str] | str
    ready: Callable = lambda d, box: True  # waits until the screen shows its data
    before: Callable = lambda d, box: None  # puts the bench in the state the screen shows
    after: Callable = lambda d, box: None
    console_ok: tuple = ()  # console messages this screen expects (a refusal)
    logged_in: bool = True
    extra: dict = field(default_factory=dict)


def _scanning(d, box):
    box["svc"].start_scan(SCAN)
    wait(d, lambda: state_of(box) == "scanning", what="the scan starts")


def _scan_done(d, box):
    wait(d, lambda: state_of(box) == "done", timeout=60, what="the scan ends")
    box["job_id"] = box["svc"].state()["job_id"]


def _bench_ready(d, box):
    wait(d, lambda: d.find_element(By.ID, "state").text.strip() not in ("", "…"), what="bench state shown")


def _previewing(d, box):
    _bench_ready(d, box)
    wait(d, lambda: loaded_img(d, "#frame"), what="the live preview")
    wait(d, lambda: "Light on" in d.find_element(By.ID, "machine-status").text, what="the light on")


def _jogging(d, box):
    """The panel's buttons move the stage: home, lift the base 1 mm, then go to a level."""
    _previewing(d, box)
    status = lambda: d.find_element(By.ID, "machine-status").text
    d.find_element(By.ID, "home").click()
    wait(d, lambda: "Ink level 60.00 mm" in status(), what="homed")
    d.find_element(By.CSS_SELECTOR, '.jogb[data-mm="1"]').click()
    wait(d, lambda: "Ink level 59.00 mm" in status(), what="jogged up 1 mm")
    d.find_element(By.ID, "goto-level").send_keys("30")
    d.find_element(By.ID, "goto").click()
    wait(d, lambda: "Ink level 30.00 mm" in status(), what="at level 30 mm")
    stage = box["svc"].factory.last.stage
    assert stage.calls[-3:] == ["home", "move 1.0000", "move 30.0000"], stage.calls


def _live_job(d, box):
    """A running job's page follows the job: it reloads itself, done, when the job ends."""
    assert d.find_element(By.ID, "job-live").is_displayed()

    def done_shown():
        try:  # the page reloads itself: an element may go stale under us
            return d.find_element(By.ID, "job-status").text.lower() == "done"
        except WebDriverException:
            return False

    wait(d, done_shown, timeout=60, what="the job page updates itself to done")
    wait(d, lambda: d.find_elements(By.ID, "report"), what="the report after the reload")


def _confirming(d, box):
    _bench_ready(d, box)
    d.find_element(By.ID, "startstop").click()
    wait(d, lambda: d.find_element(By.ID, "confirm").is_displayed(), what="the start confirmation")


def _deleting(d, box):
    d.find_element(By.ID, "delete").click()
    wait(d, lambda: d.find_element(By.ID, "delete-confirm").is_displayed(), what="the delete confirmation")


def _playing(d):
    """The 3D view tells rapids from cuts and plays the program back from its start."""
    canvas = d.find_element(By.ID, "view3d")
    wait(d, lambda: canvas.get_attribute("data-ready") == "1", what="3D view")
    assert int(canvas.get_attribute("data-cuts")) > 0 and canvas.get_attribute("data-rapids") is not None
    d.execute_script("arguments[0].scrollIntoView({block: 'center'})", d.find_element(By.ID, "play"))
    d.find_element(By.ID, "play").click()  # from the end it starts again at 0
    wait(
        d,
        lambda: 0 < float(d.find_element(By.ID, "playback").get_attribute("value")) < 1000,
        what="the program playing",
    )
    assert d.find_element(By.ID, "play").text == "Pause"


def _done_shown(d, box):
    """The bench page, opened after the job ended, says done; if not, the fault names what it showed."""

    def shown():
        return d.execute_script("const b = document.querySelector('#state'); return b ? b.innerText : null")

    try:
        wait(d, lambda: (shown() or "").lower() == "done", what="done shown")
    except TimeoutException:
        raise AssertionError(
            f"the bench page at {d.current_url} shows {shown()!r}, the daemon says "
            f"{state_of(box)!r}; browser log: {d.get_log('browser')}"
        ) from None


def _refused_setting(d, box):
    """A bad value typed and saved: the refusal shows beside its field, the save bar says so."""
    d.find_element(By.ID, "settings-form")
    box_ = d.find_element(By.ID, "set-level_step_mm")
    box_.clear()
    box_.send_keys("-1")
    d.find_element(By.ID, "settings-save").click()
    wait(
        d,
        lambda: d.find_element(By.ID, "err-level_step_mm").text == "must be positive, got -1",
        what="the refusal beside its field",
    )
    assert "Not saved" in d.find_element(By.ID, "settings-result").text
    good = (
        1.0 if box["svc"].settings()["level_step_mm"] != 1.0 else 0.75
    )  # the phone's run, then the desktop's
    box_.clear()
    box_.send_keys(str(good))  # a good value: the bar says it is stored
    d.find_element(By.ID, "settings-save").click()
    wait(d, lambda: d.find_element(By.ID, "settings-result").text.startswith("Saved at"), what="saved state")
    assert "saved" in d.find_element(By.ID, "savebar").get_attribute("class")
    assert d.find_element(By.ID, "err-level_step_mm").text == ""
    assert box["svc"].settings()["level_step_mm"] == good


SCREENS = [
    Screen("login", "/login", logged_in=False, ready=lambda d, box: d.find_element(By.ID, "password")),
    Screen("bench-idle", "/", ready=_previewing),
    Screen("bench-panel-moved", "/", ready=_jogging),
    Screen(
        "bench-confirm-start",
        "/",
        ready=_confirming,
        after=lambda d, box: d.find_element(By.ID, "confirm-back").click(),
    ),
    Screen(
        "bench-scanning",
        "/",
        before=_scanning,
        after=_scan_done,
        ready=lambda d, box: (
            _bench_ready(d, box),
            wait(d, lambda: loaded_img(d, "#frame"), what="a camera frame"),
        ),
    ),
    Screen("bench-done", "/", ready=_done_shown),
    Screen(
        "jobs", "/jobs", ready=lambda d, box: wait(d, lambda: loaded_img(d, "img.thumb"), what="thumbnails")
    ),
    Screen(
        "job",
        lambda box: f"/jobs/{box['job_id']}",
        ready=lambda d, box: (
            wait(d, lambda: loaded_img(d, "img.errimg"), what="error picture"),
            wait(
                d,
                lambda: d.find_element(By.ID, "view3d").get_attribute("data-ready") in ("1", "error"),
                what="3D view",
            ),
        ),
    ),
    Screen(
        "job-live",
        lambda box: f"/jobs/{box['svc'].state()['job_id']}",
        before=_scanning,
        ready=_live_job,
        after=_scan_done,
    ),
    Screen("job-delete", lambda box: f"/jobs/{box['job_id']}", ready=_deleting),
    Screen("job-playback", lambda box: f"/jobs/{box['job_id']}", ready=lambda d, box: _playing(d)),
    Screen("settings", "/settings", ready=lambda d, box: d.find_element(By.ID, "settings-form")),
    Screen(
        "settings-refused",
        "/settings",
        ready=lambda d, box: _refused_setting(d, box),
        console_ok=("api/settings - Failed to load resource: the server responded with a status of 400",),
    ),
    Screen(
        "system",
        "/system",
        ready=lambda d, box: wait(
            d, lambda: d.find_element(By.ID, "log-text").text not in ("", "…"), what="the log shown"
        ),
    ),
    Screen(
        "commission",
        "/commission",
        ready=lambda d, box: wait(
            d, lambda: d.find_element(By.ID, "cm-step-title").text not in ("", "…"), what="commissioning step"
        ),
    ),
    Screen(
        "calibration",
        "/calibration",
        ready=lambda d, box: wait(
            d, lambda: d.find_element(By.ID, "cal-do").text.startswith("Do step"), what="calibration steps"
        ),
    ),
    Screen(
        "api-docs",
        "/api/docs",
        ready=lambda d, box: wait(
            d, lambda: len(d.find_elements(By.CSS_SELECTOR, ".api-op")) > 15, what="API docs"
        ),
    ),
]


# -- the box and the browsers --------------------------------------------------------------------


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("screens")
    svc = BenchService(tmp / "data", FakeBench("cone"), processor=light_processor, panel_interval_s=0.05)
    run = start(svc, tmp / "data")
    ART.mkdir(parents=True, exist_ok=True)
    yield {"url": run.url, "password": run.password, "svc": svc, "tmp": tmp}
    run.stop()
    svc.close()


def make_driver(kind, tmp):
    opts = chromium_options(kind, tmp)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(DRIVER), options=opts)


def full_shot(d, kind, name) -> Path:
    """The whole page, not just the window: Chromium renders beyond the viewport for the capture."""
    import base64

    path = ART / f"screen-{kind}-{name}.png"
    got = d.execute_cdp_cmd("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True})
    path.write_bytes(base64.b64decode(got["data"]))
    assert path.stat().st_size > 3000, path
    return path


def axe_violations(d) -> list[str]:
    """axe-core's serious and critical findings on the page as it is now."""
    if not d.execute_script("return !!window.axe"):
        d.execute_script(AXE.read_text())
    res = d.execute_async_script("""
        const done = arguments[arguments.length - 1];
        axe.run(document, {resultTypes: ['violations']}).then(r => done(r.violations.map(v => ({
            id: v.id, impact: v.impact, help: v.help,
            nodes: v.nodes.slice(0, 4).map(n => n.target.join(' '))}))), e => done([{id: 'axe-error',
            impact: 'critical', help: String(e), nodes: []}]));""")
    return [
        f"{v['id']} ({v['impact']}): {v['help']} at {', '.join(v['nodes'])}"
        for v in res
        if v["impact"] in ("serious", "critical")
    ]


def console_errors(d, allowed) -> list[str]:
    return [
        e["message"]
        for e in d.get_log("browser")
        if e["level"] == "SEVERE" and not any(a in e["message"] for a in allowed)
    ]


def log_in(d, box):
    d.get(box["url"] + "/login")
    d.find_element(By.ID, "password").send_keys(box["password"])
    d.find_element(By.ID, "login-button").click()
    wait(d, lambda: d.find_elements(By.ID, "startstop"), what="logged in")


def check_screen(d, kind, screen: Screen, box) -> list[str]:
    screen.before(d, box)
    path = screen.path(box) if callable(screen.path) else screen.path
    d.get(box["url"] + path)
    screen.ready(d, box)
    time.sleep(0.3)  # late layout (images, fonts) settles
    full_shot(d, kind, screen.name)
    found = d.execute_script(CHECKS)
    faults = [f"overflow: {x}" for x in found["overflow"]]
    faults += [f"target under 44 px: {x}" for x in found["small"]]
    faults += [f"no label: {x}" for x in found["unlabelled"]]
    faults += [f"axe: {x}" for x in axe_violations(d)]
    faults += [f"console: {x}" for x in console_errors(d, screen.console_ok)]
    screen.after(d, box)
    return [f"{kind} {screen.name}: {f}" for f in faults]


@pytest.mark.parametrize("kind", list(SIZES))
def test_every_screen_fits_is_labelled_and_passes_axe(box, kind, tmp_path):
    d = make_driver(kind, tmp_path)
    try:
        d.get(box["url"] + "/login")
        if kind == "phone":  # the layout is the phone's width at its pixel ratio
            assert d.execute_script("return [window.innerWidth, window.devicePixelRatio]") == [390, 3]
        faults, seen, logged_in = [], [], False
        for screen in SCREENS:
            if screen.logged_in and not logged_in:
                log_in(d, box)
                logged_in = True
            faults += check_screen(d, kind, screen, box)
            seen.append(screen.name)
        assert seen == [s.name for s in SCREENS]
        assert not faults, "\n".join(faults)
    finally:
        d.quit()
        shutil.rmtree(tmp_path / f"profile-{kind}", ignore_errors=True)


def test_dark_mode_follows_the_phone_and_every_screen_still_passes_axe(box, tmp_path):
    """With the phone set to dark, the pages turn dark by themselves (prefers-color-scheme) and
    keep their contrast: axe finds nothing serious on any screen."""
    d = make_driver("phone", tmp_path)
    try:
        d.execute_cdp_cmd(
            "Emulation.setEmulatedMedia", {"features": [{"name": "prefers-color-scheme", "value": "dark"}]}
        )
        log_in(d, box)
        faults = []
        paths = ["/", "/jobs", "/settings", "/system", "/commission", "/calibration", "/api/docs"]
        if box.get("job_id"):
            paths.append(f"/jobs/{box['job_id']}")
        for path in paths:
            d.get(box["url"] + path)
            time.sleep(0.5)
            background = d.execute_script("return getComputedStyle(document.body).backgroundColor")
            rgb = [int(v) for v in background[background.index("(") + 1 : -1].split(",")[:3]]
            if sum(rgb) > 3 * 60:
                faults.append(f"{path}: the page stayed light ({background})")
            faults += [f"{path}: axe: {v}" for v in axe_violations(d)]
            full_shot(d, "phone-dark", path.strip("/").replace("/", "-") or "bench")
        assert not faults, "\n".join(faults)
    finally:
        d.quit()
        shutil.rmtree(tmp_path / "profile-phone", ignore_errors=True)
