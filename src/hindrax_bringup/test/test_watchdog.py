"""The hardware watchdog on /OE (its emulation and configuration) and the systemd watchdog pings
of the safety processes (hindrax_common.transport.gpio, hindrax_common.process.sd_notify, docs/watchdog.md)."""
from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.config import ConfigError, default_config_path, load_config
from hindrax_common.process.sd_notify import SafetyNotifier, notify, stale_heartbeats, watchdog_period_s
from hindrax_common.testing import child_env, ros_context, wait_until
from hindrax_common.transport.gpio import EmulatedGpioLine, WatchdogFeedLine, WatchedOutputEnable


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


# (feed levels driven, each followed by a clock advance in s; expired after each step)
FEED_TABLE = {
    "never fed": ([(None, 0.0)], [True]),
    "one edge holds for the timeout": ([(False, 0.0), (True, 0.0), (None, 0.29), (None, 0.02)], [True, False, False,
                                                                                                   True]),
    "edges every 0.1 s hold it": ([(True, 0.05), (False, 0.05)] * 6, [False] * 12),
    "staying high is no edge": ([(True, 0.1), (True, 0.1), (True, 0.05), (True, 0.1)], [False, False, False, True]),
    "released (pull-down) after edges runs out": ([(True, 0.05), ("release", 0.2), (None, 0.1)], [False, False,
                                                                                                  True]),
}


@pytest.mark.parametrize("case", list(FEED_TABLE), ids=list(FEED_TABLE))
def test_feed_line_table(case):
    steps, expected = FEED_TABLE[case]
    clock = FakeClock()
    feed = WatchdogFeedLine(0.3, clock=clock)
    got = []
    for level, advance in steps:
        if level == "release":
            feed.release()
        elif level is not None:
            feed.set_high(level)
        clock.t += advance
        got.append(feed.expired())
    assert got == expected


def test_output_enable_is_the_or_of_the_guard_line_and_the_expired_watchdog():
    clock = FakeClock()
    oe, feed = EmulatedGpioLine(pull_high=True), WatchdogFeedLine(0.3, clock=clock)
    watched = WatchedOutputEnable(oe, feed)
    assert watched.is_high()  # power-up: guard line released to its pull-up, watchdog never fed
    oe.set_high(False)
    assert watched.is_high()  # the guard lets the outputs through, the watchdog does not yet
    feed.set_high(True)
    assert not watched.is_high()
    oe.set_high(True)
    assert watched.is_high()  # the guard asserts
    oe.set_high(False)
    clock.t += 0.31
    assert watched.is_high()  # no edge for the timeout: off although the guard holds /OE low


FEED = {"esc.output_enable_feed_gpio.chip": "/dev/gpiochip0", "esc.output_enable_feed_gpio.line": 27}


@pytest.mark.parametrize("overrides,message", [
    ({**FEED, "esc.output_enable_feed_rate_hz": 10.0, "esc.output_enable_feed_timeout_s": 0.2},
     "esc.output_enable_feed_rate_hz = 10.0: allowed >= 15 Hz"),
    ({**FEED, "esc.output_enable_feed_timeout_s": 5.0}, "esc.output_enable_feed_timeout_s = 5.0"),
])
def test_feed_configuration_is_checked(overrides, message):
    with pytest.raises(ConfigError) as exc:
        load_config(default_config_path(), overrides)
    assert message in str(exc.value)
    cfg = load_config(default_config_path(), {**FEED, "esc.output_enable_feed_timeout_s": 0.33})
    assert cfg.esc.output_enable_feed_rate_hz == 10.0 and cfg.esc.output_enable_feed_gpio.line == 27


@pytest.fixture
def notify_socket(tmp_path):
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(tmp_path / "notify"))
    sock.settimeout(0.05)
    yield sock, str(tmp_path / "notify")
    sock.close()


def _received(sock):
    out = []
    while True:
        try:
            out.append(sock.recv(256).decode())
        except (TimeoutError, socket.timeout):
            return out


def test_notify_and_watchdog_period(notify_socket):
    sock, path = notify_socket
    assert not notify("READY=1", {})
    assert notify("READY=1", {"NOTIFY_SOCKET": path})
    assert _received(sock) == ["READY=1"]
    assert watchdog_period_s({"WATCHDOG_USEC": "2000000"}) == 2.0
    assert watchdog_period_s({"WATCHDOG_USEC": "x"}) is None and watchdog_period_s({}) is None
    abstract = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    name = f"hindrax-test-{os.getpid()}"
    abstract.bind("\0" + name)
    abstract.settimeout(1.0)
    try:
        assert notify("WATCHDOG=1", {"NOTIFY_SOCKET": "@" + name})
        assert abstract.recv(64) == b"WATCHDOG=1"
    finally:
        abstract.close()


def test_the_notifier_pings_only_while_every_safety_heartbeat_is_fresh(notify_socket):
    """The unit's watchdog hears WATCHDOG=1 only while the ESC's and the supervisor's beats are fresh (the guard's
    own tick sends it): one stale or never-heard beat withholds the ping, so a partial freeze ends the unit."""
    sock, path = notify_socket
    env = {"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "200000"}
    assert stale_heartbeats({"esc": 0.05, "supervisor": 0.2}, 0.2) == []
    assert stale_heartbeats({"esc": 0.21, "supervisor": math.inf}, 0.2) == ["esc", "supervisor"]
    assert stale_heartbeats({"esc": math.nan, "supervisor": 0.0}, 0.2) == ["esc"]
    n = SafetyNotifier(env)
    assert not n.update({"esc": math.inf, "supervisor": math.inf}, 0.2)  # start-up: nobody heard yet
    assert _received(sock) == [] and not n.ready
    assert n.update({"esc": 0.04, "supervisor": 0.05}, 0.2)
    assert _received(sock) == ["READY=1", "WATCHDOG=1"]
    assert not n.update({"esc": 0.25, "supervisor": 0.01}, 0.2)  # the ESC frozen
    assert not n.update({"esc": 0.01, "supervisor": 0.3}, 0.2)  # the supervisor frozen
    assert _received(sock) == [] and n.withheld == 3 and n.reason == "stale heartbeat(s): supervisor"
    assert n.update({"esc": 0.0, "supervisor": 0.0}, 0.2) and _received(sock) == ["WATCHDOG=1"]  # READY=1 once
    assert not SafetyNotifier({}).update({"esc": 0.0, "supervisor": 0.0}, 0.2)  # not under systemd: nothing


@pytest.mark.ros
def test_a_guard_without_its_esc_and_supervisor_does_not_ping_systemd(notify_socket):
    """Alone, the guard hears no ESC and no supervisor: no READY=1, no WATCHDOG=1 (a live guard used to keep the
    unit whatever the other safety processes did). Its diagnostics say why."""
    from diagnostic_msgs.msg import DiagnosticArray

    sock, path = notify_socket
    env = child_env(NOTIFY_SOCKET=path, WATCHDOG_USEC="200000")
    env.pop("HINDRAX_EMULATION_SOCKET", None)
    proc = subprocess.Popen([sys.executable, "-m", "hindrax_bringup.guard.node", "--ros-args", "--params-file",
                             str(default_config_path())], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    said: list[str] = []
    try:
        with ros_context() as ctx:
            node = rclpy.create_node("watchdog_probe", context=ctx)
            node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: said.extend(
                kv.value for st in m.status for kv in st.values if kv.key == "systemd_watchdog"), 10)
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(node)
            wait_until(lambda: said, 60, lambda: ex.spin_once(timeout_sec=0.05), "guard diagnostics")
            ex.shutdown()
        assert said[-1] == "stale heartbeat(s): esc, supervisor", said
        assert _received(sock) == []
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)


def test_units_and_the_safety_processes_use_the_systemd_watchdog():
    """The bare-metal unit waits for READY=1 and kills a unit that stops pinging within 0.2 s; the Pi's drop-in hands
    the hardware watchdog to systemd; the guard alone sends the pings (sd_notify.SafetyNotifier), the ESC and the
    supervisor none (a live one would keep the unit while the other two are frozen)."""
    import inspect
    import re
    from pathlib import Path

    from hindrax_bringup.guard import node as guard
    from hindrax_drivers.pca9685 import node as esc
    from hindrax_bringup.supervisor import node as supervisor

    docker = Path(__file__).resolve().parents[3] / "docker"
    bare = (docker / "hindrax-bare-metal.service").read_text()
    for line in ("Type=notify", "NotifyAccess=all", "WatchdogSec=200ms", "WatchdogSignal=SIGKILL",
                 "Restart=on-failure"):
        assert re.search(rf"^{line}$", bare, re.M), line
    dropin = (docker / "systemd" / "hindrax-watchdog.conf").read_text()
    assert re.search(r"^\[Manager\]$", dropin, re.M)
    seconds = int(re.search(r"^RuntimeWatchdogSec=(\d+)s$", dropin, re.M).group(1))
    assert 1 <= seconds <= 15  # the BCM2711 watchdog's longest timeout
    assert "SafetyNotifier" in inspect.getsource(guard.OutputGuardNode)
    for module in (esc, supervisor):
        assert "notif" not in inspect.getsource(module).lower(), module.__name__


def test_44_9_a_starved_guard_ages_a_dead_peer_at_wall_speed():
    """Issue 44 item 9: a heartbeat's age counted at most two tick periods (0.1 s) per gap between the watcher's
    ticks, so a watcher starved to a tick every 0.15 s aged a dead peer at 2/3 of wall speed (a stop stretched to
    1173 ms once). The guard now counts each gap in full up to its timeout: a dead peer is stale after the same wall
    time whatever the tick rate; only a gap longer than the timeout (its own freeze, which the watchdog feed
    covers) is capped, so a live peer does not look dead the moment the guard resumes."""
    from hindrax_common.node_support.liveness import AliveAge

    clock = FakeClock()
    age = AliveAge(0.2, clock=clock)  # OutputGuardNode: max_step_s = esc.guard_heartbeat_timeout_s
    age.heard()
    ticks = 0
    while age.fresh(0.2):
        clock.t += 0.15  # starved: a tick every 0.15 s instead of 0.05 s
        age.tick()
        ticks += 1
    assert ticks == 2 and age.age_s == pytest.approx(0.3)  # stale after 0.3 s of wall time, as at 20 Hz ticks
    age.heard()
    clock.t += 5.0  # the guard itself was frozen for 5 s: the peer's beats are queued, not missing
    assert age.tick() == pytest.approx(0.2) and age.fresh(0.2)


@pytest.mark.parametrize("module,files,expected", [
    ("pinctrl-bcm2711", {"pinctrl_bcm2835/parameters/persist_gpio_outputs": "N\n"}, ""),
    ("pinctrl-rp1", {"pinctrl_rp1/parameters/persist_gpio_outputs": "N\n"}, ""),
    ("pinctrl-bcm2711", {"pinctrl_bcm2835/parameters/strict_gpiod": "Y\n"}, ""),
    ("pinctrl-bcm2711", {"pinctrl_bcm2835/parameters/persist_gpio_outputs": "Y\n"},
     "keeps its level on this kernel (pinctrl_bcm2835.persist_gpio_outputs=Y)"),
    ("pinctrl-rp1", {"pinctrl_bcm2835/parameters/persist_gpio_outputs": "N\n"}, "cannot tell"),
    ("pinctrl-bcm2711", {}, "cannot tell"),
])
def test_how_a_freed_gpio_behaves_is_read_from_the_pinctrl_parameters(tmp_path, module, files, expected):
    """Issue 71.6: raspberrypi/linux PRs 6117/6150: a Raspberry Pi kernel keeps a freed output's level unless
    strict_gpiod; the guard reads which (and refuses when it cannot tell)."""
    from hindrax_common.transport.gpio import release_problem_of

    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    problem = release_problem_of(module, str(tmp_path))
    assert (problem == "") if not expected else (expected in problem and "strict_gpiod" in problem), problem


def test_a_persisting_emulated_line_keeps_its_level_when_released():
    line = EmulatedGpioLine(pull_high=True, persist=True)
    line.set_high(False)
    line.release()
    assert not line.is_high() and "keeps its level" in line.release_problem()
    assert EmulatedGpioLine(pull_high=True).release_problem() == ""
