"""Commissioning from a phone: headless Chromium at 390 x 844 @ 3x against the daemon's real
BenchService on the simulated bench (firmware under simavr, the virtual camera).

One run goes through every step; another cancels at each step and then starts a scan from the
dashboard, which the bench must take (no step may keep the bench). Screenshots go to
tests/artifacts/web/phone-commission-*.png.
"""

import shutil

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.needs("chromium")]

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from test_web_browser import ART, make_driver, shot, wait  # noqa: E402
from test_web_real_service import light_processor  # noqa: E402

from appliance.daemon.service import BenchService  # noqa: E402
from appliance.web.server import start  # noqa: E402

# a short scan: the dashboard's Start takes the bench, the test stops it again
SHORT_SCAN = {
    "levels_to_mm": 28.0,
    "levels_from_mm": 22.0,
    "level_step_mm": 2.0,
    "settle_s": 0.0,
}  # above the cone


@pytest.fixture(scope="module")
def factory():
    from appliance.sim.fakes import SimulatedBenchFactory, small_rig

    f = SimulatedBenchFactory("cone", small_rig(320, 240))
    yield f
    f.close()


@pytest.fixture
def box(factory, tmp_path):
    svc = BenchService(tmp_path / "daemon", factory, processor=light_processor, panel_interval_s=0.1)
    svc.update_settings(SHORT_SCAN)
    run = start(svc, tmp_path / "web")
    ART.mkdir(parents=True, exist_ok=True)
    yield {"url": run.url, "password": run.password, "svc": svc, "tmp": tmp_path}
    run.stop()
    svc.close()


@pytest.fixture
def phone(box):
    d, _ = make_driver("phone", box["tmp"])
    try:
        d.get(box["url"] + "/login")
        d.find_element(By.ID, "password").send_keys(box["password"])
        d.find_element(By.ID, "login-button").click()
        wait(d, lambda: d.find_elements(By.ID, "startstop"), what="dashboard")
        yield d
    finally:
        d.quit()
        shutil.rmtree(box["tmp"] / "profile-phone", ignore_errors=True)


def readable_on_a_phone(d, what):
    """No sideways scrolling, and every visible button, link-button and field is a thumb target
    (>= 44 CSS px high; a checkbox by its label, which toggles it) with a label a screen reader
    can say."""
    sw, iw = d.execute_script("return [document.documentElement.scrollWidth, window.innerWidth]")
    assert sw <= iw, (what, sw, iw)
    small = d.execute_script("""
        const out = [];
        document.querySelectorAll('main button, main a.button, main input, main select').forEach((e) => {
          const tap = e.type === 'checkbox' && e.labels && e.labels.length ? e.labels[0] : e;
          const r = tap.getBoundingClientRect();
          if (!r.width || e.type === 'hidden') return;
          const named = e.labels && e.labels.length || e.getAttribute('aria-label') || e.textContent.trim();
          if (r.height < 44 || !named) out.push((e.id || e.name || e.tagName) + ' ' + Math.round(r.height) + 'px');
        });
        return out;""")
    assert not small, (what, small)


def bench_takes_a_scan(d, url):
    """From the dashboard: Start scan is confirmed and taken (the button turns into Stop), then
    stopped with a second tap."""
    d.get(url + "/")
    btn = d.find_element(By.ID, "startstop")
    wait(d, lambda: btn.is_enabled() and btn.text == "Start scan…", what="start button ready")
    btn.click()
    wait(d, lambda: d.find_element(By.ID, "confirm").is_displayed(), what="start confirmation")
    d.find_element(By.ID, "confirm-start").click()
    wait(
        d,
        lambda: btn.text == "Stop scan" or d.find_element(By.ID, "action-error").is_displayed(),
        timeout=30,
        what="scan started",
    )
    assert btn.text == "Stop scan", d.find_element(By.ID, "action-error").text
    btn.click()
    btn.click()
    wait(
        d,
        lambda: d.find_element(By.ID, "state").text.lower() in ("cancelled", "done"),
        timeout=60,
        what="scan stopped",
    )


def test_the_calibration_can_be_cancelled_at_each_step_and_the_bench_then_scans(box, phone):
    d = phone
    steps = ["home", "target", "detect"]
    for n in range(1, len(steps) + 1):
        d.get(box["url"] + "/calibration")
        do = d.find_element(By.ID, "cal-do")
        wait(d, lambda: do.text.startswith("Do step 1"), what="calibration at its first step")
        for step in steps[:n]:
            do.click()
            # detect finds no board on the virtual camera unless it shows one: either way the step ends
            wait(
                d,
                lambda: (
                    not do.get_attribute("disabled")
                    and "Working" not in d.find_element(By.ID, "cal-result").text
                ),
                timeout=60,
                what=f"step {step} ends",
            )
        assert "holds the bench" in d.find_element(By.ID, "cal-hold").text
        readable_on_a_phone(d, f"calibration after {steps[n - 1]}")
        shot(d, "phone", f"calibration-held-{steps[n - 1]}")
        d.find_element(By.ID, "cal-cancel").click()
        wait(d, lambda: "cancelled" in d.find_element(By.ID, "cal-result").text, timeout=30, what="cancelled")
        assert "free" in d.find_element(By.ID, "cal-hold").text
        assert box["svc"].calibration()["holds_bench"] is False
        bench_takes_a_scan(d, box["url"])
    # and the whole guided calibration goes through: the simulated bench lays the board on the
    # base when the target step asks for it, and the virtual camera shows it
    d.get(box["url"] + "/calibration")
    do = d.find_element(By.ID, "cal-do")
    for step in ("home", "target", "detect"):
        wait(d, lambda: do.text.endswith(step) and do.is_enabled(), timeout=60, what=f"step {step}")
        do.click()
    wait(
        d, lambda: "corners 54" in d.find_element(By.ID, "cal-detected").text, timeout=60, what="board found"
    )
    wait(
        d,
        lambda: d.execute_script(
            "const i=document.getElementById('cal-frame');return i.complete && i.naturalWidth > 0"
        ),
        what="preview",
    )
    shot(d, "phone", "calibration-detected")
    wait(d, lambda: do.text.endswith("accept") and do.is_enabled(), what="accept")
    do.click()
    wait(d, lambda: do.text.endswith("home"), timeout=30, what="stored")
    cals = box["svc"].store.calibrations()
    assert len(cals) == 1 and cals[0]["source"] == "guided" and cals[0]["report"]["plane_rms_mm"] < 0.1, cals
    bench_takes_a_scan(d, box["url"])


# -- the commissioning page ------------------------------------------------------------------

FIND_BUTTON = """
    const [label, click] = arguments;
    const b = [...document.querySelectorAll('main button')].find((e) => e.offsetParent !== null
        && !e.disabled && (e.textContent.trim().startsWith(label) || (e.getAttribute('aria-label') || '') === label));
    if (b && click) { b.scrollIntoView({block: 'center'}); b.click(); }
    return !!b;"""


def can_press(d, label):
    """A visible, enabled button whose text starts with `label` (or whose aria-label is it)."""
    return d.execute_script(FIND_BUTTON, label, False)


def press(d, label, timeout=30):
    # found and clicked in one script: the page redraws its buttons as the daemon's answers come
    wait(d, lambda: d.execute_script(FIND_BUTTON, label, True), timeout=timeout, what=f"button {label!r}")


def active(box):
    return box["svc"].commissioning()["active"]


def statuses(box):
    return {s["id"]: s["status"] for s in box["svc"].commissioning()["steps"]}


def open_commissioning(d, box):
    d.get(box["url"] + "/commission")
    wait(d, lambda: d.find_element(By.ID, "cm-step-title").text not in ("", "…"), what="commissioning page")


def note(d):
    return d.find_element(By.ID, "cm-note").text


# the page's fetch, with the answer to a level-zero measurement held back 1.5 s
LATE_MEASURE_ANSWER = """
const fetched = window.fetch;
window.lateMeasureAnswered = false;
window.fetch = (url, opts) => fetched(url, opts).then((r) => !String(url).endsWith("/level_zero/measure") ? r :
  new Promise((done) => setTimeout(() => { done(r); setTimeout(() => { window.lateMeasureAnswered = true; }, 300); }, 1500)));
"""


def test_commissioning_goes_through_every_step_on_a_phone(box, phone, tmp_path):
    d = phone
    open_commissioning(d, box)
    assert d.find_element(By.ID, "cm-step-title").text == "Level zero"  # the sequence starts here
    assert "100 x 70 mm" in d.find_element(By.ID, "cm-board-size").text
    for link in ("cm-board-pdf", "cm-board-png"):
        href = d.find_element(By.ID, link).get_attribute("href")
        assert d.execute_script("return fetch(arguments[0]).then(r => r.status)", href) == 200, href
    readable_on_a_phone(d, "commissioning, first visit")
    shot(d, "phone", "commission-1-start")

    # level zero: measured on the bench (the base rises until its top breaks the ink), then accepted
    press(d, "Start")
    press(d, "Measure level zero")
    wait(d, lambda: can_press(d, "Accept and store"), timeout=120, what="level zero measured")
    d.execute_script("document.getElementById('cm-step').scrollIntoView()")
    readable_on_a_phone(d, "level zero measured")
    shot(d, "phone", "commission-1b-level-zero-measured")
    press(d, "Accept and store")
    wait(d, lambda: note(d) == "Level zero stored.", what="level zero stored")
    assert d.find_element(By.ID, "cm-step-title").text == "Camera lens and liquid plane"

    # camera: three tilted views for the lens, the flat board for the plane
    press(d, "Start")
    for n in (1, 2, 3):
        press(d, "Take a tilted view", timeout=60)
        wait(d, lambda: can_press(d, f"Take a tilted view ({n} taken)"), timeout=60, what=f"view {n}")
    wait(
        d,
        lambda: d.execute_script(
            "const i=document.getElementById('cm-frame');return i.complete && i.naturalWidth > 0"
        ),
        what="preview",
    )
    press(d, "Measure the flat board")
    wait(d, lambda: can_press(d, "Accept and store"), timeout=120, what="plane measured")
    d.execute_script("document.getElementById('cm-step').scrollIntoView()")
    shot(d, "phone", "commission-1c-camera-measured")
    press(d, "Accept and store")
    wait(d, lambda: note(d) == "Camera lens and liquid plane stored.", what="camera stored")

    # tank: entered as width x depth, the figure shown
    assert d.find_element(By.ID, "cm-step-title").text == "Tank area"
    readable_on_a_phone(d, "tank step")
    d.execute_script("document.getElementById('cm-step').scrollIntoView()")
    shot(d, "phone", "commission-2-tank")
    held = d.find_element(By.ID, "cm-in-level_held")
    assert held.get_attribute("type") == "checkbox" and not held.is_selected()  # by default the ink falls
    held.click()  # this tank has an overflow
    press(d, "Save the tank area")
    wait(d, lambda: note(d) == "Tank area stored.", what="tank stored")
    shown = d.find_element(By.ID, "cm-results").text
    assert "150 x 150 mm = 22500 mm², the ink's level held by an overflow" in shown, shown
    assert box["svc"].commissioning()["steps"][2]["result"]["surface_falls"] is False

    # meniscus: a scan of the 25.4 mm ball, processed with the fitted model and measured
    ball = d.find_element(By.ID, "cm-in-diameter_mm")
    assert ball.get_attribute("value") == "25.4"
    press(d, "Start: the ball goes on the base")
    press(d, "Scan the ball")
    wait(
        d,
        lambda: "Reference scan:" in d.find_element(By.ID, "cm-busy").text,
        timeout=60,
        what="scan progress",
    )
    d.execute_script("document.getElementById('cm-step').scrollIntoView()")
    shot(d, "phone", "commission-3-scanning")
    press(d, "Accept and store", timeout=600)
    wait(d, lambda: note(d) == "Meniscus (reference ball) stored.", what="meniscus stored")
    ref = d.find_element(By.ID, "cm-reference").text
    meniscus = box["svc"].commissioning()["steps"][3]
    err = meniscus["result"]["reference"]["mean_abs_error_mm"]
    assert ref.startswith(f"This box measures the 25.4 mm ball to {err:.2f} mm"), ref
    assert statuses(box) == {"level_zero": "done", "camera": "done", "tank": "done", "meniscus": "done"}
    results = d.find_element(By.ID, "cm-results").text
    assert results.count(" UTC") == 4, results  # every result with its date
    assert d.find_element(By.ID, "cm-step-title").text == "This box is commissioned"
    d.execute_script("window.scrollTo(0, 0)")
    readable_on_a_phone(d, "commissioned")
    shot(d, "phone", "commission-4-done")

    # one file out, the ink changed, the same file back in
    downloads = box["tmp"] / "downloads-phone"
    d.find_element(By.ID, "cm-export").click()
    wait(
        d,
        lambda: (
            list(downloads.glob("inkslice-commissioning-*.json")) and not list(downloads.glob("*.crdownload"))
        ),
        what="export downloaded",
    )
    exported = next(downloads.glob("inkslice-commissioning-*.json"))
    import json

    doc = json.loads(exported.read_text())
    assert doc["format"] == "inkslice.commissioning/1" and set(doc["results"]) == set(statuses(box))
    press(d, "The ink was changed")
    wait(d, lambda: "Ink change recorded" in d.find_element(By.ID, "cm-files-note").text, what="ink change")
    assert statuses(box) == {"level_zero": "stale", "camera": "done", "tank": "done", "meniscus": "stale"}
    assert d.find_element(By.ID, "cm-step-title").text == "Level zero"  # the sequence starts over there
    assert "Ink last changed" in d.find_element(By.ID, "cm-ink").text
    assert len(d.find_elements(By.CSS_SELECTOR, "#cm-results .b-stale")) == 2
    d.execute_script("window.scrollTo(0, 0)")
    shot(d, "phone", "commission-5-ink-changed")
    d.find_element(By.ID, "cm-import-file").send_keys(str(exported))
    press(d, "Import")
    wait(d, lambda: "Imported" in d.find_element(By.ID, "cm-files-note").text, what="import")
    d.execute_script("document.getElementById('cm-files').scrollIntoView()")
    readable_on_a_phone(d, "after import")
    shot(d, "phone", "commission-6-files")


def test_a_cancel_at_each_commissioning_step_gives_the_bench_back(box, phone):
    d = phone

    def cancel_then_scan(step, title, pressed=False):
        if not pressed:
            press(d, "Cancel")
        wait(
            d,
            lambda: note(d).startswith(f"{title} cancelled"),
            timeout=60,
            what=lambda: f"{step} cancelled; the page says {note(d)!r}",
        )
        assert active(box) is None and "The bench is free" in note(d)
        assert (
            box["svc"].commissioning()["steps"][["level_zero", "camera", "tank", "meniscus"].index(step)][
                "status"
            ]
            == "missing"
        )  # nothing was stored
        bench_takes_a_scan(d, box["url"])
        open_commissioning(d, box)

    def go_to(title):
        press(d, f"Do this step: {title}")
        wait(d, lambda: d.find_element(By.ID, "cm-step-title").text == title, what=title)

    open_commissioning(d, box)
    # level zero, while its measurement runs: the stage stops and the bench is free at once.
    # The stopped measurement's own answer (an error) may reach the phone after the cancel's;
    # it is held back here so that it always does, and must not undo what the cancel showed.
    d.execute_script(LATE_MEASURE_ANSWER)
    press(d, "Start")
    press(d, "Measure level zero")
    wait(d, lambda: "Working" in d.find_element(By.ID, "cm-busy").text, what="measuring")
    assert active(box)["holds_bench"]
    shot(d, "phone", "commission-cancel-level-zero")
    press(d, "Cancel")
    wait(d, lambda: d.execute_script("return window.lateMeasureAnswered"), what="the late answer")
    assert note(d).startswith("Level zero cancelled") and not d.find_element(By.ID, "cm-error").is_displayed()
    assert not d.find_element(By.ID, "cm-busy").is_displayed()
    cancel_then_scan("level_zero", "Level zero", pressed=True)

    # camera, with one view taken; a scan asked for meanwhile is refused with the way out
    go_to("Camera lens and liquid plane")
    press(d, "Start")
    press(d, "Take a tilted view", timeout=60)
    wait(d, lambda: can_press(d, "Take a tilted view (1 taken)"), timeout=60, what="one view")
    d.get(box["url"] + "/")
    press(d, "Start scan")
    press(d, "Start now")  # the confirmation
    wait(d, lambda: d.find_element(By.ID, "action-fix").is_displayed(), what="refusal with a link")
    assert "'camera' holds the bench" in d.find_element(By.ID, "action-error").text
    shot(d, "phone", "commission-held-dashboard")
    d.find_element(By.CSS_SELECTOR, "#action-fix a").click()
    wait(
        d, lambda: d.find_element(By.ID, "cm-step-title").text == "Camera lens and liquid plane", what="back"
    )
    assert "holding the bench" in d.find_element(By.ID, "cm-step-count").text
    cancel_then_scan("camera", "Camera lens and liquid plane")

    # tank: nothing runs, cancel leaves without storing the figures typed in
    go_to("Tank area")
    d.find_element(By.ID, "cm-in-width_mm").clear()
    d.find_element(By.ID, "cm-in-width_mm").send_keys("-120")
    press(d, "Save the tank area")  # refused, naming the field
    wait(d, lambda: "width_mm" in d.find_element(By.ID, "cm-error").text, what="refusal shown")
    assert d.find_element(By.ID, "cm-error").is_displayed() and statuses(box)["tank"] == "missing"
    cancel_then_scan("tank", "Tank area")

    # meniscus, during the reference ball's scan: the scan job is cancelled with it
    go_to("Meniscus (reference ball)")
    press(d, "Start: the ball goes on the base")
    press(d, "Scan the ball")
    wait(d, lambda: box["svc"].state()["state"] == "scanning", timeout=60, what="reference scan running")
    job_id = active(box)["job_id"]
    cancel_then_scan("meniscus", "Meniscus (reference ball)")
    assert box["svc"].job(job_id)["status"] == "cancelled"

    # skip: stored as skipped, and the sequence goes on with the next open step
    go_to("Tank area")
    press(d, "Skip this step")
    wait(d, lambda: note(d) == "Tank area skipped.", what="tank skipped")
    assert statuses(box)["tank"] == "skipped"
    assert d.find_element(By.ID, "cm-step-title").text == "Meniscus (reference ball)"

    # skip during the ball's scan: the scan stops with it and the bench takes the next one
    press(d, "Start: the ball goes on the base")
    press(d, "Scan the ball")
    wait(d, lambda: box["svc"].state()["state"] == "scanning", timeout=60, what="reference scan running")
    job_id = active(box)["job_id"]
    press(d, "Skip this step")
    wait(d, lambda: note(d) == "Meniscus (reference ball) skipped.", timeout=60, what="meniscus skipped")
    assert statuses(box)["meniscus"] == "skipped" and box["svc"].job(job_id)["status"] == "cancelled"
    bench_takes_a_scan(d, box["url"])
