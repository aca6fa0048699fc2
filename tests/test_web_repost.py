"""Re-posting from the phone: a finished job's page makes a program for another
dialect from the job's height map (no rescan), twice, and both download byte for
byte as the job's files."""

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.needs("chromium")]

webdriver = pytest.importorskip("selenium.webdriver")
from polling import wait_until  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import Select  # noqa: E402
from test_web_browser import ART, make_driver, shot, wait  # noqa: E402
from web_helpers import bench_service, part_processor  # noqa: E402

from appliance.web.server import start  # noqa: E402


@pytest.fixture(scope="module")
def finished_job(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("repost")
    svc = bench_service(tmp / "bench", processor=part_processor)
    run = start(svc, tmp / "data")
    ART.mkdir(parents=True, exist_ok=True)
    job_id = svc.start_scan({})
    wait_until(lambda: svc.job(job_id)["status"] == "done", 60, what="the scan to be done", every=0.1)
    yield {"url": run.url, "password": run.password, "svc": svc, "job": job_id}
    run.stop()
    svc.close()


def _repost(d, dialect):
    form = d.find_element(By.ID, "repost-form")
    Select(form.find_element(By.NAME, "dialect")).select_by_value(dialect)
    sc = form.find_element(By.NAME, "scallop_mm")
    sc.clear()
    sc.send_keys("0.3")  # coarse: the test is about the round trip, not the finish
    d.find_element(By.ID, "repost-go").click()


def test_a_finished_job_is_posted_again_for_two_dialects_and_both_download(finished_job, tmp_path):
    box = finished_job
    job_id = box["job"]
    d, downloads = make_driver("phone", tmp_path)
    try:
        d.get(box["url"] + "/login")
        d.find_element(By.ID, "password").send_keys(box["password"])
        d.find_element(By.ID, "login-button").click()
        wait(d, lambda: "/login" not in d.current_url, what="logged in")
        d.get(f"{box['url']}/jobs/{job_id}")
        wait(d, lambda: d.find_elements(By.ID, "repost-form"), what="the re-post form")
        names = {}
        for dialect in ("grbl", "fanuc"):
            name = f"{job_id}-finish-ball6-{dialect}.nc"
            _repost(d, dialect)
            wait(
                d,
                lambda: d.find_elements(By.CSS_SELECTOR, f'a[data-file="{name}"]'),
                timeout=300,
                what=f"the {dialect} program among the downloads",
            )
            names[dialect] = name
        shot(d, "phone", "job-reposted")
        for dialect, name in names.items():
            link = d.find_element(By.CSS_SELECTOR, f'a[data-file="{name}"]')
            d.execute_script("arguments[0].scrollIntoView()", link)
            link.click()
            want = box["svc"].job_file(job_id, name).read_bytes()
            saved = link.get_attribute("download")
            wait(
                d,
                lambda: (downloads / saved).is_file() and (downloads / saved).read_bytes() == want,
                timeout=30,
                what=f"{dialect} download",
            )
        got = {
            n: (downloads / d.find_element(By.CSS_SELECTOR, f'a[data-file="{n}"]').get_attribute("download"))
            for n in names.values()
        }
        assert "%" in got[names["fanuc"]].read_text().splitlines()[0]  # Fanuc's tape marks
        assert "M0" in got[names["grbl"]].read_text().splitlines()[:8]  # GRBL: pause for the tool
        assert f"{names['grbl'][:-3]}.preview.json" in box["svc"].job(job_id)["outputs"]
    finally:
        d.quit()
