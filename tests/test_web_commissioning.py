"""Commissioning from a phone: headless Chromium at 390 x 844 @ 3x against the daemon's real
BenchService on the simulated bench (firmware under simavr, the virtual camera).

One run goes through every step; another cancels at each step and then starts a scan from the
dashboard, which the bench must take (no step may keep the bench). Screenshots go to
tests/artifacts/web/phone-commission-*.png.
"""
import os
import shutil
import time

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow]

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By                    # noqa: E402

from appliance.daemon.service import BenchService               # noqa: E402
from appliance.web.demo import start                            # noqa: E402
from test_web_browser import ART, CHROMIUM, DRIVER, make_driver, shot, wait   # noqa: E402
from test_web_real_service import light_processor               # noqa: E402
from web_helpers import NoUsb                                   # noqa: E402

if not (os.path.exists(CHROMIUM) and os.path.exists(DRIVER)):
    pytest.skip("Debian chromium/chromium-driver not installed", allow_module_level=True)

# a short scan: the dashboard's Start takes the bench, the test stops it again
SHORT_SCAN = {"levels_to_mm": 6.0, "levels_from_mm": 2.0, "level_step_mm": 2.0, "settle_s": 0.0}


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
    run = start(svc, tmp_path / "web", config={"usb": NoUsb()})
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
    (>= 44 CSS px high) with a label a screen reader can say."""
    sw, iw = d.execute_script("return [document.documentElement.scrollWidth, window.innerWidth]")
    assert sw <= iw, (what, sw, iw)
    small = d.execute_script("""
        const out = [];
        document.querySelectorAll('main button, main a.button, main input, main select').forEach((e) => {
          const r = e.getBoundingClientRect();
          if (!r.width || e.type === 'hidden') return;
          const named = e.labels && e.labels.length || e.getAttribute('aria-label') || e.textContent.trim();
          if (r.height < 44 || !named) out.push((e.id || e.name || e.tagName) + ' ' + Math.round(r.height) + 'px');
        });
        return out;""")
    assert not small, (what, small)


def bench_takes_a_scan(d, url):
    """From the dashboard: Start scan is taken (the button turns into Stop), then stopped."""
    d.get(url + "/")
    btn = d.find_element(By.ID, "startstop")
    wait(d, lambda: btn.is_enabled() and btn.text == "Start scan", what="start button ready")
    btn.click()
    wait(d, lambda: btn.text == "Stop scan" or d.find_element(By.ID, "action-error").is_displayed(),
         timeout=30, what="scan started")
    assert btn.text == "Stop scan", d.find_element(By.ID, "action-error").text
    btn.click()
    wait(d, lambda: d.find_element(By.ID, "state").text.lower() in ("cancelled", "done"), timeout=60,
         what="scan stopped")


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
            wait(d, lambda: not do.get_attribute("disabled") and "Working" not in
                 d.find_element(By.ID, "cal-result").text, timeout=60, what=f"step {step} ends")
        assert "holds the bench" in d.find_element(By.ID, "cal-hold").text
        readable_on_a_phone(d, f"calibration after {steps[n - 1]}")
        shot(d, "phone", f"calibration-held-{steps[n - 1]}")
        d.find_element(By.ID, "cal-cancel").click()
        wait(d, lambda: "cancelled" in d.find_element(By.ID, "cal-result").text, timeout=30, what="cancelled")
        assert "free" in d.find_element(By.ID, "cal-hold").text
        assert box["svc"].calibration()["holds_bench"] is False
        bench_takes_a_scan(d, box["url"])
