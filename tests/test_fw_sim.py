"""The protocol, homing, limits and e-stop, against the real firmware under simavr.

Each test reads as one clause of appliance/firmware/stepper/PROTOCOL.md and checks it
on the unmodified ELF through the HIL harness (a fresh MCU per test)."""

import threading
import time

import pytest
from fw_helpers import RawLink, err

from appliance.errors import DeviceError, SettingError
from appliance.hw import protocol as P
from appliance.hw.stage import SerialStage
from appliance.sim.hil import SimulatedBench

pytestmark = pytest.mark.simavr
F_CPU = 16e6


def home(link, seq=900):
    assert link.ask(seq, "HOME").ok
    st = link.wait_idle()
    assert st.state == "idle" and st.homed
    return st


# ---- identify, reset reasons, watchdog ----
def test_id_reports_the_protocol_version_and_a_power_on_reset(link):
    r = link.ask(1, "ID")
    info = P.parse_identity(r.payload)
    assert r.ok and info["name"] == "inkslice-stepper" and info["proto"] == P.PROTO_VERSION
    assert info["reset"] == "power_on"


def test_a_reset_pin_pulse_is_reported_as_external_and_the_banner_says_so(bench, link):
    bench.reset_mcu(wait_boot=True)
    banner = link.line()
    assert isinstance(banner, P.Banner) and banner.reset == "external"
    assert P.parse_identity(link.ask(2, "ID").payload)["reset"] == "external"


def test_a_reset_that_cuts_a_line_off_still_shows_its_banner(bench, link):
    """A reset mid-line (here: mid-banner, the simulation slowed to a crawl as on a loaded
    machine) leaves a fragment without its newline. The next banner opens with a bare
    newline, so the fragment fails on its own and the banner after it arrives intact (it
    ran on from the fragment into one damaged line, and the reset went unseen)."""
    bench.set_speed(0.01)
    bench.reset_mcu(wait_boot=True)  # back at the banner's first byte
    bench.reset_mcu(wait_boot=True)
    bench.set_speed(0)
    banner = link.line(timeout=3)
    assert isinstance(banner, P.Banner) and banner.reset == "external"


def test_reboot_goes_through_the_watchdog(link):
    assert link.ask(3, "REBOOT").ok
    banner = link.line(timeout=2)
    assert isinstance(banner, P.Banner) and banner.reset == "watchdog"
    assert link.status().flags["fresh_boot"]


# ---- framing ----
def test_a_line_with_a_bad_checksum_is_answered_error_1_with_seq_0(link):
    link.send_raw(b"\n5 ID*0000\n")
    r = link.reply()
    assert (r.seq, r.ok, r.error) == (0, False, err("bad_checksum"))


def test_unknown_verbs_bad_arguments_and_long_lines_have_their_codes(link):
    assert link.ask(6, "JUMP").error == err("unknown_command")
    assert link.ask(7, "MOVE", "12x").error == err("bad_argument")
    assert link.ask(8, "GET", "nonsense").error == err("unknown_setting")
    link.send_raw(b"\n" + b"9" * 80 + b"\n")
    r = link.reply()
    assert (r.seq, r.error) == (0, err("line_too_long"))
    assert link.ask(10, "ID").ok  # and the link still works


def test_status_byte_is_answered_mid_line_without_disturbing_the_line(link):
    data = P.encode_command(11, "STATUS")
    link.send_raw(data[:5])
    st = link.status()  # '?' in the middle of the line
    assert st.state == "idle" and st.flags["fresh_boot"]
    link.send_raw(data[5:])
    r = link.reply(11)
    assert r.ok and r.payload.split()[0] == "idle"


# ---- moves, duplicates, soft limits ----
def test_move_before_homing_is_refused_not_homed(bench, link):
    assert link.ask(12, "MOVE", 8000).error == err("not_homed")
    assert bench.stats()["steps_up"] + bench.stats()["steps_down"] == 0


def test_homing_finds_the_switch_and_the_stage_ends_at_the_pulloff(bench, link):
    st = home(link)
    assert st.position == P.SETTINGS["home_pulloff"].default
    assert bench.stage_position_steps() == st.position  # the firmware's 0 is where the switch closes


def test_homing_starting_on_the_switch_backs_off_first(bench, link):
    bench.place_stage(-0.5)
    assert link.status().flags["limit_bottom"]
    st = home(link)
    assert bench.stage_position_steps() == st.position == 1600


def test_a_resent_move_is_acknowledged_again_but_not_executed_twice(bench, link):
    home(link)
    line = link.send(20, "MOVE", 48000)
    assert link.reply(20).ok
    link.send_raw(line)  # the host "lost" the ok: same line again
    r = link.reply(20)
    assert r.ok  # a second execution would say error:8 busy
    assert link.wait_idle().position == 48000
    link.send_raw(line)
    assert link.reply(20).ok
    backoff, pulloff = P.SETTINGS["home_backoff"].default, P.SETTINGS["home_pulloff"].default
    assert bench.stats()["steps_up"] == backoff + pulloff + (48000 - pulloff)  # homing, then the move once
    assert bench.stage_position_steps() == 48000


def test_a_move_past_a_soft_limit_is_refused_and_nothing_moves(bench, link):
    home(link)
    before = bench.stats()
    assert link.ask(21, "MOVE", P.SETTINGS["soft_max"].default + 1).error == err("soft_limit")
    assert link.ask(22, "MOVE", -1).error == err("soft_limit")
    after = bench.stats()
    assert (after["steps_up"], after["steps_down"]) == (before["steps_up"], before["steps_down"])


def test_impossible_settings_are_refused(link):
    assert link.ask(23, "SET", "pulse_us", 0).error == err("setting_out_of_range")
    assert link.ask(24, "SET", "soft_min", 200000).error == err("settings_inconsistent")
    assert link.ask(25, "SET", "home_fast", 20000).error == err("settings_inconsistent")


# ---- hard limits and the emergency stop ----
def test_hitting_the_top_switch_stops_the_move_and_raises_an_alarm(fw_build):
    with SimulatedBench(speed=0, stage_mm=5.0, top_switch_mm=12.0) as bench:  # a short machine
        link = RawLink(bench.port)
        try:
            home(link)
            assert link.ask(31, "MOVE", 24000).ok  # 15 mm: inside the soft limits, past the switch
            st = link.wait_idle()
            assert st.state == "alarm" and st.alarm == "hard_limit_top"
            assert st.flags["limit_top"] and not st.homed
            assert bench.stage_position_steps() == 19200  # stopped on the switch, not past it
            assert bench.stats()["stalls"] == 0
            assert link.ask(32, "MOVE", 8000).error == err("not_homed")
            home(link, 33)  # HOME clears the alarm
        finally:
            link.close()


def test_hitting_the_home_switch_outside_homing_is_a_bottom_hard_limit(bench, link):
    home(link)
    assert link.ask(34, "SET", "soft_min", -5000).ok
    assert link.ask(35, "MOVE", -4000).ok
    st = link.wait_idle()
    assert (st.state, st.alarm, st.flags["limit_bottom"], st.homed) == (
        "alarm",
        "hard_limit_bottom",
        True,
        False,
    )
    assert bench.stage_position_steps() == 0  # stopped where the switch closed


def test_emergency_stop_halts_within_one_step_period(bench, link):
    home(link)
    assert link.ask(40, "MOVE", 140000).ok
    time.sleep(0.05)
    assert link.status().state == "moving"
    link.send_raw(P.RT_ESTOP)
    st = link.wait_idle()
    assert st.state == "estop" and st.alarm == "emergency_stop" and not st.homed
    s = bench.stats()
    byte_cycles = 11 * F_CPU / 117647  # simavr delivers the byte one frame later
    step_period = F_CPU / P.SETTINGS["max_rate"].default
    late = s["last_step_cycle"] - (s["estop_feed_cycle"] + byte_cycles)
    print(f"last step {late / 16:.1f} us after the stop byte arrived (one step = {step_period / 16:.1f} us)")
    assert late < step_period
    assert 1600 < bench.stage_position_steps() < 140000
    assert link.ask(41, "MOVE", 8000).error == err("not_homed")


# ---- step signal timing ----
@pytest.mark.parametrize("driver,pulse_us,setup_us", [("drv8825", 2, 1), ("a4988", 1, 1)])
def test_step_pulse_width_and_dir_setup_meet_the_driver_preset(bench, link, driver, pulse_us, setup_us):
    assert link.ask(50, "DRIVER", driver).ok
    assert link.ask(51, "GET", "pulse_us").payload == str(pulse_us)
    home(link)
    assert link.ask(52, "MOVE", 20000).ok
    link.wait_idle()
    s = bench.stats()
    assert s["min_pulse_cycles"] >= pulse_us * 16
    assert s["min_dir_setup_cycles"] >= setup_us * 16


# ---- EEPROM settings ----
def test_settings_survive_a_reset_and_a_damaged_eeprom_restores_defaults(bench, link):
    assert link.ask(60, "SET", "accel", 123456).ok
    bench.reset_mcu(wait_boot=True)
    assert link.ask(61, "GET", "accel").payload == "123456"
    assert "settings=ok" in link.ask(62, "ID").payload
    bench.eeprom(20, bench.eeprom(20) ^ 0x10)  # flip one bit of the stored image
    bench.reset_mcu(wait_boot=True)
    assert "settings=defaults" in link.ask(63, "ID").payload
    assert link.status().flags["settings_defaulted"]
    assert link.ask(64, "GET", "accel").payload == str(P.SETTINGS["accel"].default)


# ---- the Python driver on the simulated bench ----
def test_driver_homes_moves_and_the_stage_really_is_there(bench):
    stage = SerialStage(bench.port, timeout=10.0)
    try:
        assert stage.identify()["proto"] == P.PROTO_VERSION
        stage.home()
        stage.move_to(12.5)
        assert bench.stage_position_mm() == pytest.approx(12.5, abs=1e-9)
        stage.move_by(-0.25)
        assert bench.stage_position_mm() == pytest.approx(12.25, abs=1e-9)
        st = stage.status()
        assert (st.state, st.position_steps, st.homed) == ("idle", 19600, True)
        with pytest.raises(SettingError, match="soft limits"):
            stage.move_to(200.0)
    finally:
        stage.close()


def _reset(bench, noise):
    bench.reset_mcu()


def _forged_estop(bench, noise):
    noise.send_raw(P.RT_ESTOP)  # a Ctrl-X the driver never sent
    time.sleep(0.05)


@pytest.mark.parametrize(
    "lose, resets, estops",
    [
        (_reset, 1, 0),  # seen as a banner, a fresh_boot status and a refused MOVE: one reset
        (_forged_estop, 0, 1),  # the next MOVE refused with not_homed; the state says estop
    ],
    ids=["mcu-reset", "forged-estop"],
)
def test_a_position_lost_between_moves_is_found_again_and_counted_once(bench, lose, resets, estops):
    stage = SerialStage(bench.port, timeout=10.0)
    noise = RawLink(bench.port)  # a second writer on the same line
    try:
        stage.home()
        stage.move_to(5.0)
        lose(bench, noise)
        stage.move_to(7.0)
        assert bench.stage_position_mm() == pytest.approx(7.0, abs=1e-9)
        assert stage.counters["rehomes"] == 1
        assert (stage.counters["resets_seen"], stage.counters["spurious_estops"]) == (resets, estops)
        assert stage.counters["damaged_lines"] == 0  # the banner's opening newline is no damage
    finally:
        noise.close()
        stage.close()


def test_driver_stop_is_an_emergency_stop_and_later_moves_need_a_home(bench):
    stage = SerialStage(bench.port, timeout=10.0)
    try:
        stage.home()
        stage.stop()
        assert stage.status().state == "estop"
        with pytest.raises(DeviceError, match="emergency-stopped"):
            stage.move_to(3.0)
        stage.home()
        stage.move_to(3.0)
        assert bench.stage_position_mm() == pytest.approx(3.0, abs=1e-9)
    finally:
        stage.close()


def test_driver_gives_up_within_its_timeout_when_the_line_is_dead(bench):
    stage = SerialStage(bench.port, timeout=1.0)
    try:
        bench.set_fault("rx", "drop", 1.0)
        t = time.monotonic()
        with pytest.raises(DeviceError, match="no valid reply to ID"):
            stage.transact("ID")
        assert time.monotonic() - t < 1.0 + 2.0  # its timeout, plus slack for a loaded machine
    finally:
        stage.close()


def test_simulated_bench_at_real_time_starts_and_identifies(fw_build):
    """(Its start-up time, < 2 s, is measured by benches/firmware.py.)"""
    with SimulatedBench(speed=1.0) as b:
        stage = SerialStage(b.port, timeout=10.0)
        assert stage.info["proto"] == P.PROTO_VERSION
        stage.close()


def test_driver_recovers_from_an_emergency_stop_byte_forged_by_line_noise(bench):
    """PROTOCOL.md rule 6: a Ctrl-X the driver never sent is handled like a reset."""
    stage = SerialStage(bench.port, timeout=10.0)
    noise = RawLink(bench.port)  # a second writer on the same line
    try:
        stage.home()
        t = threading.Timer(0.02, noise.send_raw, args=(P.RT_ESTOP,))
        t.start()
        stage.move_to(60.0)
        t.join()
        assert bench.stage_position_mm() == pytest.approx(60.0, abs=1e-9)
        assert stage.counters["spurious_estops"] == 1 and stage.counters["rehomes"] == 1
    finally:
        noise.close()
        stage.close()


def test_the_bench_flags_bytes_a_real_2_byte_fifo_would_lose(fw_build):
    """simavr buffers 64 received bytes; the chip keeps 2.  The harness feeds
    the wire one frame at a time and counts every byte that completes while
    3 are unread.  A firmware whose receive interrupt is too slow (a test
    build that spends 400 us per byte) must be caught; the real firmware,
    here and in every other test and the soak, must count 0."""
    from fw_helpers import make

    make("slow-rx")
    from fw_helpers import BUILD

    with SimulatedBench(speed=0, elf=BUILD / "slow-rx.elf") as b:
        link = RawLink(b.port)
        try:
            link.send_raw(P.encode_command(1, "ID") * 3)
            time.sleep(0.3)
            assert b.stats()["rx_overruns"] > 0
        finally:
            link.close()
    with SimulatedBench(speed=1.0) as b:
        link = RawLink(b.port)
        try:
            b.eeprom(0, 0)  # the next boot rewrites the image (~0.2 s)
            b.reset_mcu()
            link.send_raw(P.encode_command(1, "ID") * 3)  # ... while the host already talks
            time.sleep(0.4)
            for seq in range(3, 13):
                assert link.ask(seq, "STATUS").ok
            assert b.stats()["rx_overruns"] == 0
        finally:
            link.close()
