"""One definition of the daemon (daemon/facade.py): the in-process service, the socket's
client and the socket's method list all follow the Protocol, so the web cannot meet a
method one side has and the other lacks."""

from __future__ import annotations

from pathlib import Path

from appliance.daemon import facade, rpc
from appliance.daemon.service import BenchService
from appliance.web.adapter import WebService


def test_bench_service_has_every_facade_method_with_its_parameters():
    # getattr on the class: holds wherever in the daemon package a method is written
    assert facade.differences(BenchService) == []


def test_the_socket_client_has_every_facade_method_with_its_parameters():
    assert facade.differences(rpc.BenchClient) == []


def test_the_socket_serves_exactly_the_facade_calls():
    assert set(rpc.METHODS) == set(facade.methods()) - set(facade.NOT_CALLS)
    assert len(rpc.METHODS) == len(set(rpc.METHODS))
    assert "subscribe" not in rpc.METHODS and "close" not in rpc.METHODS  # streamed / local only


def test_the_client_replays_exactly_the_methods_the_facade_marks_as_reads():
    assert rpc.BenchClient.READ_ONLY == facade.read_only()
    assert facade.read_only() <= set(rpc.METHODS)
    assert {"state", "jobs", "job", "job_file", "settings", "latest_frame"} <= facade.read_only()


def test_no_method_that_changes_the_bench_is_marked_as_a_read():
    # sent twice after a daemon restart, any of these would act twice
    changes = {
        "start_scan",
        "cancel",
        "resume",
        "update_settings",
        "delete_job",
        "rename_job",
        "reprocess",
        "repost",
        "import_scan",
        "calibrate",
        "commission",
        "import_commissioning",
        "ink_changed",
        "preview",
        "home_stage",
        "jog",
        "goto_level",
        "export_to_usb",
        "restore",
        "test_webhook",
    }
    assert changes <= set(facade.methods())
    assert changes & facade.read_only() == set()


def test_the_web_wraps_every_facade_call():
    missing = [name for name in rpc.METHODS if not callable(getattr(WebService, name, None))]
    assert missing == []


def test_every_facade_method_says_what_it_does():
    for name in facade.methods():
        assert (getattr(facade.Bench, name).__doc__ or "").strip(), name


class _Drifted:
    """A service that lost a method and renamed a parameter: the check must see both."""

    def state(self) -> dict:
        return {}

    def job(self, ident: str) -> dict:
        return {}

    def cancel(self, wait_s: float = 30.0) -> None:  # an extra parameter with a default: allowed
        pass

    def jog(self, mm: float, speed) -> dict:  # an extra one without a default: not
        return {}

    def export_to_usb(self, job_id: str, name: str = "program.nc", stick=None, release=True) -> dict:
        return {}


def test_the_check_reports_a_missing_method_a_renamed_parameter_and_a_changed_default():
    found = "\n".join(facade.differences(_Drifted))
    assert "_Drifted.start_scan: missing" in found
    assert "_Drifted.job(self, ident" in found
    assert "_Drifted.jog: an extra parameter without a default" in found
    assert "_Drifted.export_to_usb(" in found  # name's default differs
    assert "_Drifted.cancel" not in found and "_Drifted.state" not in found


def test_the_facade_module_imports_nothing_of_the_daemon():
    # the web imports it: it must stay a bare declaration
    source = Path(facade.__file__).read_text()
    assert "from ." not in source and "import appliance" not in source
