"""``hindrax pool rehearse``: one command gives a newcomer the README's pool day without a vehicle.

From the colcon install (test/conftest.py), as the README says to run it: the command starts the live pool and the
installed pool_test launch on this worker's domain (the internal one) with the gateway on another (the topside one),
and prints the two shells' environments. Then, as the README's pool day does: ``hindrax health`` in the vehicle's
shell says READY, ``hindrax arm`` and ``hindrax disarm`` in the topside's shell answer, a heave campaign starts and
a second ``ident start`` is refused while it runs, ``hindrax disarm`` ends it and ``hindrax reset`` + ``hindrax arm``
bring the vehicle back from the topside, the pool's operator attaches and removes the ballast
through the command's input, and ``quit`` stops everything cleanly. Before, a newcomer had to
piece this together from the live pool module, a hand-edited vehicle file and a test. The block's
second launch (``model_file:=``) takes the model of the session's README walk (test_pool_day.py,
``pool_day_model``: the same launch's campaign, bag and fit, its heave checked against the pool's
truth; run alone, a heave campaign and its ``ident bag`` here make one), and there ``control
hold`` prints the altitude held.
"""
from __future__ import annotations

import os
import queue
import shlex
import signal
import subprocess
import threading
import time

import pytest
import yaml
from hindrax_test_support.helpers import fresh_domain, until_done

pytestmark = [pytest.mark.vehicle_launch, pytest.mark.ros, pytest.mark.timeout(2400)]

WAIT_S = 180.0  # a loaded two-core machine starts ten Python processes
CAMPAIGN_S = 900.0  # a heave campaign of two levels, or its bag's identification, on a loaded two-core machine


def _exports(path: str) -> dict[str, str]:
    out = {}
    for line in open(path).read().splitlines():
        words = shlex.split(line)
        if words[:1] == ["export"]:
            key, _, value = words[1].partition("=")
            out[key] = value
    return out


class _Lines:
    """The command's output lines, read by a thread of their own (a select() on a buffered text pipe misses lines
    already in the buffer)."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc, self.lines, self._queue = proc, [], queue.Queue()
        threading.Thread(target=lambda: [self._queue.put(x) for x in proc.stdout] + [self._queue.put(None)],
                         daemon=True).start()

    def until(self, prefix: str, timeout_s: float) -> str:
        """The next line starting with ``prefix`` (the lines before it kept in :attr:`lines`)."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                line = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                line = None
            if line is None:
                raise AssertionError(f"no line starting {prefix!r} within {timeout_s:g} s (exit {self.proc.poll()}): "
                                     f"{self.lines[-20:]}")
            self.lines.append(line.rstrip("\n"))
            if line.startswith(prefix):
                return line


def test_the_rehearsal_runs_the_readme_pool_day_commands(colcon_install, tmp_path, pool_day_model):
    install = colcon_install
    with fresh_domain() as topside:
        proc = subprocess.Popen(["hindrax", "pool", "rehearse", "--topside-domain", str(topside), "--dir",
                                 str(tmp_path)], env=install.env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, bufsize=1)
        out = _Lines(proc)
        seen = out.lines
        try:
            out.until("rehearsal: ", 120)
            shells = {m: _exports(str(tmp_path / f"{m}.env")) for m in ("vehicle", "topside")}
            assert shells["vehicle"]["ROS_DOMAIN_ID"] == install.env["ROS_DOMAIN_ID"]
            assert shells["topside"]["ROS_DOMAIN_ID"] == str(topside) and shells["topside"]["HINDRAX_VEHICLE"]
            assert any(s.startswith("# topside shell (topside domain") for s in seen), seen
            vehicle_env, topside_env = ({**install.env, **shells[m]} for m in ("vehicle", "topside"))
            health = subprocess.run(["hindrax", "health", "--launch", "hindrax_onboard/pool_test.launch.xml",
                                     f"output_dir:={tmp_path / 'runs'}", "--timeout", str(WAIT_S)], env=vehicle_env,
                                    capture_output=True, text=True, timeout=WAIT_S + 60)
            assert health.returncode == 0 and "READY to dive" in health.stdout, health.stdout + health.stderr
            # as test_pool_day's README walk does
            for command in ("arm", "disarm"):
                answer = until_done(lambda: subprocess.run(
                    ["hindrax", command], env=topside_env, capture_output=True, text=True, timeout=120),
                    f"hindrax {command} on the topside")
                vehicle = shells["topside"]["HINDRAX_VEHICLE"]
                assert answer.stdout.strip() == f"{vehicle}: {command}ed", answer
            # issue 74.4: ident continue with nothing awaited (the ESC disarmed) answers with the reason
            t0 = time.monotonic()
            cont = subprocess.run(["hindrax", "ident", "continue"], env=topside_env, capture_output=True, text=True,
                                  timeout=120)
            print(f"ident continue while disarmed answered in {time.monotonic() - t0:.1f} s")
            assert cont.returncode == 1 and cont.stdout.strip() == "not continued: no identification goal is running", \
                cont
            # issue 74 "done when", in part: a campaign, a second start and a continue during it, a disarm during
            # it and the way back from the topside (hindrax reset, hindrax arm)
            name = shells["topside"]["HINDRAX_VEHICLE"]
            hindrax = lambda *a: subprocess.run(["hindrax", *a], env=topside_env, capture_output=True,  # noqa: E731
                                                text=True, timeout=WAIT_S)
            until_done(lambda: hindrax("arm"), "hindrax arm before the campaign")
            campaign = subprocess.Popen(["hindrax", "ident", "start", "--dofs", "heave", "--levels", "2"],
                                        env=topside_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                        bufsize=1)
            try:
                lines = _Lines(campaign)
                lines.until("campaign started: heave", WAIT_S)
                second = hindrax("ident", "start", "--dofs", "heave", "--levels", "2")
                assert second.returncode == 1 and "a campaign is already running" in second.stderr, second
                t0 = time.monotonic()
                cont = hindrax("ident", "continue")
                print(f"ident continue during the campaign answered in {time.monotonic() - t0:.1f} s")
                assert cont.returncode == 1 and cont.stdout.startswith("not continued: "), cont
                assert hindrax("disarm").stdout.strip() == f"{name}: disarmed"
                result = lines.until("result: ", WAIT_S)
                assert result.startswith("result: not complete: ") and "disarmed" in result, result
                assert campaign.wait(60) == 1
            finally:
                if campaign.poll() is None:
                    campaign.send_signal(signal.SIGINT)
                    campaign.wait(60)
            reset = hindrax("reset")
            assert reset.returncode == 0 and reset.stdout.startswith(f"{name}: "), reset
            until_done(lambda: hindrax("arm"), "hindrax arm after the reset")
            # the README's hold and its printed result: on the second day's launch, with the model
            assert hindrax("disarm").stdout.strip() == f"{name}: disarmed"
            # a whole heave campaign for the README's offline steps below, unless the session's README walk has
            # identified one already (test/conftest.py pool_day_model: the same launch, campaign, bag and fit)
            if "model" not in pool_day_model:
                until_done(lambda: hindrax("arm"), "hindrax arm for the campaign")
                t0 = time.monotonic()
                full = subprocess.run(["hindrax", "ident", "start", "--dofs", "heave", "--levels", "2"],
                                      env=topside_env, capture_output=True, text=True, timeout=CAMPAIGN_S)
                print(f"heave campaign: {time.monotonic() - t0:.0f} s; {full.stdout.strip().splitlines()[-1]}")
                assert full.returncode == 0 and "result: complete" in full.stdout, full.stdout[-3000:] + full.stderr
                assert hindrax("disarm").stdout.strip() == f"{name}: disarmed"
            # issue 74.5: the README's read-out of the supervisor's status, without the ros2 CLI
            status_topic = f"/{shells['topside']['HINDRAX_VEHICLE']}/supervisor/status"
            echo = subprocess.run(["hindrax", "topic", "echo", status_topic, "--count", "1", "--timeout", str(WAIT_S)],
                                  env=topside_env, capture_output=True, text=True, timeout=WAIT_S + 60)
            assert echo.returncode == 0 and echo.stdout.endswith("---\n"), echo
            status = yaml.safe_load(echo.stdout.rsplit("---", 1)[0])  # disarm_cause among its values after a stop
            assert list(status) == ["level", "name", "message", "hardware_id", "values"], status
            # issue 74.2: a second rehearsal on the vehicle's domain is refused, naming what it found
            second = subprocess.run(["hindrax", "pool", "rehearse", "--topside-domain", str(topside), "--dir",
                                     str(tmp_path / "second")], env=install.env, stdin=subprocess.DEVNULL,
                                    capture_output=True, text=True, timeout=120)
            assert second.returncode == 1 and "hindrax pool rehearse: refused: ROS domain " in second.stderr and \
                "refusing to start a second vehicle on it" in second.stderr, second
            for code in ("attach_ballast", "remove_ballast"):
                proc.stdin.write(code + "\n")
                proc.stdin.flush()
                assert out.until("pool: ", 30).strip() == f"pool: {code} done"
            proc.stdin.write("quit\n")
            proc.stdin.flush()
            out.until("rehearsal: stopped", 120)
            assert proc.wait(60) == 0
        finally:
            if proc.poll() is None:  # Ctrl-C: the command stops its launch and pool (a SIGKILL would orphan them)
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(90)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        # the README's day goes on: ident bag, control model, the second launch with the model, the hold
        (bag,) = [p for p in (tmp_path / "runs").iterdir() if p.is_dir()]
        model = pool_day_model.get("model")
        if model is None:
            t0 = time.monotonic()
            fit = subprocess.run(["hindrax", "ident", "bag", str(bag)], env=vehicle_env, capture_output=True,
                                 text=True, timeout=CAMPAIGN_S)
            print(f"ident bag: {time.monotonic() - t0:.0f} s")
            assert fit.returncode == 0, fit.stdout[-3000:] + fit.stderr
            (made,) = [p for p in (tmp_path / "runs").iterdir() if p.name.startswith(bag.name + "_ident_")]
            model = made / "identification.yaml"
        shown = subprocess.run(["hindrax", "control", "model", "--model", str(model)], env=vehicle_env,
                               capture_output=True, text=True, timeout=WAIT_S)
        assert shown.returncode == 0 and "heave" in shown.stdout, shown
        day2 = subprocess.Popen(["hindrax", "pool", "rehearse", "--topside-domain", str(topside), "--dir",
                                 str(tmp_path / "day2"), f"model_file:={model}"], env=install.env,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                bufsize=1)
        out2 = _Lines(day2)
        try:
            out2.until("rehearsal: ", 120)
            topside_env = {**install.env, **_exports(str(tmp_path / "day2" / "topside.env"))}  # its own key
            until_done(lambda: hindrax("arm"), "hindrax arm with the model")
            hold = hindrax("control", "hold", "--altitude-m", "0.9", "--watch-s", "5")
            print(hold.stdout.strip())
            assert hold.returncode == 0 and f"{name}: over the last 5 s (" in hold.stdout and \
                "altitude 0.900 m held: measured " in hold.stdout, hold
            assert hindrax("control", "release").returncode == 0
            assert hindrax("disarm").stdout.strip() == f"{name}: disarmed"
            day2.stdin.write("quit\n")
            day2.stdin.flush()
            out2.until("rehearsal: stopped", 120)
            assert day2.wait(60) == 0
        finally:
            if day2.poll() is None:
                day2.send_signal(signal.SIGINT)
                try:
                    day2.wait(90)
                except subprocess.TimeoutExpired:
                    day2.kill()
                    day2.wait()
    assert any((tmp_path / "runs").iterdir()), "the launch's recorder wrote no bag"
    assert sorted(p.name for p in (tmp_path / "logs").iterdir()), os.listdir(tmp_path)
