"""Safety benchmark rows of the vehicle's authority (docs/architecture.md §8.2): a sealed internal graph and signed
operator requests.

The layout of :func:`hindrax_tools.benchmarks.safety.run_processes` (the ESC node, the
supervisor and the output guard, each in its own process on the vehicle's transport) with the
gateway beside them, started as ``python -m hindrax_bringup.gateway.node`` on the layout's internal
domain and a topside domain of its own, with an operator key for the vehicle (``HINDRAX_KEYS_DIR``):

* ``internal_sockets_reachable_from_network``: UDP sockets (:mod:`hindrax_common.process.proc_sockets`) of the ESC,
  supervisor, guard and the gateway's internal process bound outside 127.0.0.1 and the multicast groups (target
  0). The gateway's topside process is not counted: it must reach the tether;
* ``operator_{unsigned,wrong_key,replayed}_requests_accepted``: of :data:`REQUESTS` (:data:`QUICK_REQUESTS`) arm
  requests sent to ``/<vehicle>/arm`` from the topside domain, each unsigned, signed with another key, or a copy of
  an arm the gateway had accepted (the ESC disarmed again in between), those answered with success (target 0). A
  freshly signed arm before and after them is answered armed (the path works; otherwise the bench stops)."""
from __future__ import annotations

import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from domain_coordinator import domain_id
from hindrax_bringup.gateway.operator_signing import KEYS_DIR_ENV, Signer, create_key, load_key
from hindrax_common.process.proc_sockets import child_pids, exposed, udp_sockets
from hindrax_common.testing import wait_until

from hindrax_msgs.srv import SetArmed, SignedTrigger
from std_srvs.srv import Trigger

from . import call, probe_spinning, run_alone, start_logged
from .safety import running_layout

#: arm requests of each kind (unsigned, wrong key, replayed); with ``--quick``
REQUESTS, QUICK_REQUESTS = 10, 3
WAIT_S = 60.0
#: what each kind of request of :func:`signing_rows` is
KINDS = {"unsigned": "unsigned", "wrong_key": "signed with another key",
         "replayed": "each a copy of an arm the gateway had accepted"}


def exposure_row(sockets_by_process: dict[str, list[tuple[str, int]]]) -> dict:
    """The row ``internal_sockets_reachable_from_network`` from process label -> its UDP sockets (address, port):
    value = how many are reachable from the network (:func:`~hindrax_common.process.proc_sockets.exposed`)."""
    found = exposed(sockets_by_process)
    total = sum(len(s) for s in sockets_by_process.values())
    return {"name": "internal_sockets_reachable_from_network", "value": sum(len(s) for s in found.values()),
            "unit": "sockets", "target": 0,
            "note": f"of {total} UDP sockets of {', '.join(sockets_by_process)} (/proc); gateway topside process not "
                    "counted" + (f"; reachable: {found}" if found else "")}


def signing_rows(answers: dict[str, list[bool]]) -> list[dict]:
    """Rows ``operator_<kind>_requests_accepted`` from kind -> the ``success`` of each answer to such a request."""
    return [{"name": f"operator_{kind}_requests_accepted", "value": sum(bool(a) for a in got),
             "unit": f"of {len(got)} requests", "target": 0,
             "note": f"arm requests to the gateway from the topside, {KINDS.get(kind, kind)}; freshly signed arms "
                     "before and after them were accepted"} for kind, got in answers.items()]


@contextmanager
def gateway_running(lay, topside: int, keys_dir: str | None = None) -> Iterator[subprocess.Popen]:
    """The gateway (``python -m hindrax_bringup.gateway.node``) beside the layout ``lay``
    (:func:`~hindrax_tools.benchmarks.safety.running_layout`), on its internal domain and the topside domain
    ``topside`` (LOCALHOST, the shipped file's range), with operator keys from ``keys_dir`` (none: every operator
    request refused); yields its process once its internal participant has sockets, and stops it on the way out."""
    env = dict(lay.env, **({KEYS_DIR_ENV: keys_dir} if keys_dir else {}))
    argv = [lay.py, "-m", "hindrax_bringup.gateway.node", "--ros-args", "--params-file", lay.config,
            "-p", f"topside_domain_id:={topside}"]
    gateway = start_logged(lay.tmp / "gateway.log", argv, env=env)
    try:
        wait_until(lambda: "internal domain" in (lay.tmp / "gateway.log").read_text(), WAIT_S, None, "gateway started")
        wait_until(lambda: len(child_pids(gateway.pid)) == 1 and udp_sockets(child_pids(gateway.pid)[0]),
                   WAIT_S, None, "gateway's internal participant")
        yield gateway
    finally:
        gateway.terminate()
        gateway.wait(30)


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: fewer requests); returns its result rows."""
    n = QUICK_REQUESTS if quick else REQUESTS
    with running_layout("hindrax-bench-authority-") as lay, domain_id() as topside, \
            tempfile.TemporaryDirectory(prefix="hindrax-bench-keys-") as keys:
        vehicle = lay.vehicle
        key = load_key(create_key(Path(keys) / f"{vehicle}.key"))
        lay.ensure()
        with gateway_running(lay, topside, keys) as gateway:
            pids = {name: p.pid for name, p in lay.procs.items()}
            pids["gateway internal"] = child_pids(gateway.pid)[0]
            wait_until(lambda: all(udp_sockets(pid) for pid in pids.values()), WAIT_S, None, "every participant")
            rows = [exposure_row({name: udp_sockets(pid) for name, pid in pids.items()})]
            with probe_spinning(topside, "bench_operator") as (node, _ex, spin):
                client = node.create_client(SignedTrigger, f"/{vehicle}/arm")
                wait_until(client.service_is_ready, WAIT_S, spin, f"/{vehicle}/arm on the topside")
                signer = Signer(key, vehicle)
                wait_until(lambda: lay.arm_client.service_is_ready() and lay.reset_client.service_is_ready(),
                           WAIT_S, None, "ESC and supervisor up")

                def signed_arm():
                    """A freshly signed arm until the ESC takes it (it refuses while the guard holds /OE); then
                    disarmed again through the ESC itself. Returns the accepted request."""
                    got = []

                    def attempt() -> bool:
                        lay.call(lay.reset_client, Trigger.Request())
                        req = signer.sign_message("arm", SignedTrigger.Request())
                        if call(client, req, spin, WAIT_S).success:
                            got.append(req)
                        return bool(got)
                    wait_until(attempt, WAIT_S, None, "a signed arm accepted")
                    lay.call(lay.arm_client, SetArmed.Request(arm=False))
                    return got[0]

                accepted = signed_arm()
                other = Signer(bytes(32), vehicle)
                answers = {"unsigned": [], "wrong_key": [], "replayed": []}
                for _ in range(n):
                    unsigned = SignedTrigger.Request()
                    answers["unsigned"].append(call(client, unsigned, spin, WAIT_S).success)
                    wrong = other.sign_message("arm", SignedTrigger.Request())
                    answers["wrong_key"].append(call(client, wrong, spin, WAIT_S).success)
                    answers["replayed"].append(call(client, accepted, spin, WAIT_S).success)
                    if any(v[-1] for v in answers.values()):
                        lay.call(lay.arm_client, SetArmed.Request(arm=False))
                signed_arm()  # the path still worked after them
            return rows + signing_rows(answers)


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
