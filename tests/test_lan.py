"""The box on the LAN: install.sh lays out an Avahi service file that advertises the web UI as
_http._tcp on the port the web unit listens on."""

import re
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

from web_helpers import bench_service

REPO = Path(__file__).resolve().parents[1]


def web_port() -> int:
    unit = (REPO / "systemd/inkslice-web.service").read_text()
    return int(re.search(r"^ExecStart=.* --port (\d+)", unit, re.M).group(1))


def test_install_root_lays_out_the_avahi_service_for_the_web_ui(tmp_path):
    root = tmp_path / "root"
    r = subprocess.run(
        [str(REPO / "systemd/install.sh"), "--root", str(root)], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    path = root / "etc/avahi/services/inkslice.service"
    assert path.is_file() and oct(path.stat().st_mode & 0o777) == "0o644"
    group = ET.parse(path).getroot()
    assert group.tag == "service-group"
    assert "%h" in group.find("name").text and group.find("name").get("replace-wildcards") == "yes"
    services = group.findall("service")
    assert [s.find("type").text for s in services] == ["_http._tcp"]
    assert int(services[0].find("port").text) == web_port() == 8080
    assert "path=/" in [t.text for t in services[0].findall("txt-record")]


def test_a_real_install_names_the_host_inkslice_and_starts_avahi():
    script = (REPO / "systemd/install.sh").read_text()
    real = script.split('if [ -n "$ROOT" ]; then', 1)[1]  # what runs on the box itself
    assert "avahi-daemon" in real and "hostnamectl set-hostname inkslice" in real
    assert "systemctl enable avahi-daemon.service" in real


def test_the_demo_can_listen_on_the_lan_and_says_where_a_phone_finds_it(tmp_path):
    from appliance.cli import build_parser
    from appliance.web.server import banner, start

    args = build_parser().parse_args(["demo", "--serve-only", "--host", "0.0.0.0"])
    assert args.host == "0.0.0.0"
    assert build_parser().parse_args(["demo"]).host == "127.0.0.1"  # this machine only, unless asked
    assert "--host $(HOST)" in (REPO / "Makefile").read_text()
    svc = bench_service(tmp_path / "bench")
    run = start(svc, tmp_path / "data", host="0.0.0.0")
    try:
        text = banner(run)
        assert (
            f":{run.server.effective_port}/" in text and "From a phone on the same network: http://" in text
        )
    finally:
        run.stop()
        svc.close()
