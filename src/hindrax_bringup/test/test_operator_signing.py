"""Signed operator commands (hindrax_bringup.gateway.operator_signing): MAVLink-2-style HMAC-SHA256 with a 32-byte
key, a 48-bit timestamp near the vehicle's clock, a link id, a persisted replay cache. Unsigned, wrong-key, replayed,
re-targeted, out-of-range, ahead and stale requests are refused with one line and counted; the key file is created
with mode 0600 and refused when others can read it. Issue 71: +k*2^48 replays, lock-outs, replays after a restart
and file paths in refusals (each test below fails on the old per-link-timestamp Verifier)."""
from __future__ import annotations

import hmac
import os
import stat
from hashlib import sha256
from pathlib import Path

import pytest

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hindrax_bringup.gateway.operator_signing import (AHEAD_LIMIT, KEY_BYTES, STALE_LIMIT, TIMESTAMP_MAX,
                                                      OperatorKeyError, Signature, Signer, Verifier, create_key,
                                                      key_path, load_key, mac, replay_path, signed_payload)

KEY = bytes(range(32))
OTHER = bytes(range(1, 33))


def test_the_mac_is_hmac_sha256_over_name_relay_link_timestamp_and_payload():
    expected = hmac.new(KEY, b"hindrax-operator-v1\0" + b"alpha\0arm\0" + bytes([7]) + (1234).to_bytes(6, "little")
                        + b"body", sha256).digest()
    assert mac(KEY, "alpha", "arm", 7, 1234, b"body") == expected


def test_a_signed_request_is_accepted_once_and_its_replay_refused():
    signer, verifier = Signer(KEY, "alpha", link_id=3), Verifier(KEY, "alpha")
    sig = signer.sign("arm", b"")
    assert verifier.check("arm", sig, b"") is None
    why = verifier.check("arm", sig, b"")
    assert why is not None and why.startswith("arm: refused: replayed") and "\n" not in why
    assert verifier.counts["accepted"] == 1 and verifier.counts["replayed"] == 1


def test_unsigned_wrong_key_and_retargeted_requests_are_refused_and_counted():
    verifier = Verifier(KEY, "alpha")
    assert verifier.check("arm", Signature(0, 0, bytes(32)), b"").startswith("arm: refused: unsigned")
    wrong = Signer(OTHER, "alpha").sign("arm", b"")
    assert verifier.check("arm", wrong, b"").startswith("arm: refused: bad signature")
    disarm = Signer(KEY, "alpha").sign("disarm", b"")
    assert verifier.check("arm", disarm, b"").startswith("arm: refused: bad signature")  # a disarm is not an arm
    bravo = Signer(KEY, "bravo").sign("arm", b"")
    assert verifier.check("arm", bravo, b"").startswith("arm: refused: bad signature")  # nor another vehicle's
    tampered = Signer(KEY, "alpha").sign("controller/setpoint", b"depth 1.0")
    assert verifier.check("controller/setpoint", tampered, b"depth 9.0").startswith("controller/setpoint: refused")
    assert verifier.counts == {"accepted": 0, "unsigned": 1, "malformed": 0, "bad_signature": 4, "ahead": 0,
                               "stale": 0, "replayed": 0, "unrecorded": 0, "no_key": 0}


T0 = 300_000_000_000  # a vehicle clock, timestamp units (10 us): about 35 days after the epoch


def _sign(link: int, ts: int, relay: str = "arm", payload: bytes = b"", key: bytes = KEY) -> Signature:
    return Signature(link, ts, mac(key, "alpha", relay, link, ts, payload))


def test_timestamps_must_lie_within_the_window_around_the_vehicle_clock():
    verifier = Verifier(KEY, "alpha", now=lambda: T0)
    assert verifier.check("arm", _sign(1, T0 - STALE_LIMIT - 1), b"").startswith("arm: refused: stale: this PC's "
                                                                                 "clock is 60.0 s behind")
    assert verifier.check("arm", _sign(1, T0 - STALE_LIMIT), b"") is None
    assert verifier.check("arm", _sign(1, T0 + AHEAD_LIMIT), b"") is None
    assert verifier.check("arm", _sign(2, T0 - 5), b"") is None  # not ordered per link: any fresh MAC is fine
    assert verifier.counts["stale"] == 1 and verifier.counts["accepted"] == 3


def test_a_replay_with_k_times_2_48_added_to_the_timestamp_is_refused():
    """Finding 71.1: the MAC covers 48 bits; the old Verifier compared all 64 and took +2^48 as newer."""
    verifier = Verifier(KEY, "alpha", now=lambda: T0)
    sig = _sign(4, T0)
    assert verifier.check("reset", sig, b"") is not None  # a reset's signature is not an arm's
    sig = _sign(4, T0, "reset")
    assert verifier.check("reset", sig, b"") is None
    for k in (1, 2, 1000):
        why = verifier.check("reset", Signature(4, sig.timestamp + k * (1 << 48), sig.mac), b"")
        assert why is not None and why.startswith("reset: refused: link id 4 or timestamp"), why
    assert verifier.check("reset", Signature(4 + 256, sig.timestamp, sig.mac), b"").startswith("reset: refused")
    assert verifier.counts["accepted"] == 1 and verifier.counts["malformed"] == 4


def test_a_clock_ahead_is_refused_named_and_the_request_never_becomes_acceptable():
    """Finding 71.2: a PC a day ahead neither locks the operator out nor leaves a request replayable tomorrow."""
    clock = [T0]
    verifier = Verifier(KEY, "alpha", now=lambda: clock[0])
    day = 86_400 * 100_000
    ahead = _sign(9, T0 + day)
    why = verifier.check("arm", ahead, b"")
    assert why == ("arm: refused: this PC's clock is 86400.0 s ahead of the vehicle's (at most 5 s): fix its time "
                   "(chrony), or the vehicle's if it has not synchronised since boot"), why
    assert verifier.check("arm", _sign(9, T0), b"") is None  # the operator, same link, right clock: accepted
    assert verifier.check("arm", _sign(10, T0 + 1), b"") is None  # and on a new link
    clock[0] = T0 + day  # a day later, the captured request replayed
    assert verifier.check("arm", ahead, b"").startswith("arm: refused: replayed")


def test_an_accepted_request_is_refused_by_a_restarted_verifier_even_with_its_clock_behind(tmp_path):
    """Finding 71.3: replay protection lives in a file written before the request is accepted (mode 0600)."""
    state = tmp_path / "alpha.replay"
    clock = [T0]
    sig = _sign(3, T0)
    assert Verifier(KEY, "alpha", now=lambda: clock[0], state=state).check("arm", sig, b"") is None
    assert stat.S_IMODE(state.stat().st_mode) == 0o600 and not list(tmp_path.glob("*.tmp"))
    assert Verifier(KEY, "alpha", now=lambda: clock[0], state=state).check("arm", sig, b"").startswith(
        "arm: refused: replayed")  # restarted 7 s later, or at once
    clock[0] = T0 + 2 * STALE_LIMIT  # the MAC leaves the cache: the floor keeps the request dead
    assert Verifier(KEY, "alpha", now=lambda: clock[0], state=state).check("arm", _sign(5, clock[0]), b"") is None
    clock[0] = T0  # a reboot without a real-time clock: the vehicle's clock back where it was
    assert Verifier(KEY, "alpha", now=lambda: clock[0], state=state).check("arm", sig, b"").startswith(
        "arm: refused: replayed")


def test_an_unreadable_replay_cache_refuses_until_the_clock_has_passed_what_it_may_have_held(tmp_path):
    state = tmp_path / "alpha.replay"
    state.write_text("not a cache\n")
    verifier = Verifier(KEY, "alpha", now=lambda: T0, state=state)
    assert "unreadable" in verifier.problem
    assert verifier.check("arm", _sign(1, T0), b"").startswith("arm: refused: replayed")
    assert verifier.check("arm", _sign(1, T0 + AHEAD_LIMIT + 1), b"").startswith("arm: refused: this PC's clock")


def test_a_cache_that_cannot_be_written_refuses_the_request(tmp_path):
    verifier = Verifier(KEY, "alpha", now=lambda: T0, state=tmp_path / "missing" / "alpha.replay")
    why = verifier.check("arm", _sign(1, T0), b"")
    assert why.startswith("arm: refused: the vehicle could not record it") and str(tmp_path) not in why
    assert verifier.counts == dict(verifier.counts, accepted=0, unrecorded=1)


def test_refusals_name_no_file_of_the_vehicle(tmp_path, monkeypatch):
    """Finding 71.4: the no-key and unsigned refusals go to any topside caller."""
    monkeypatch.setenv("HINDRAX_KEYS_DIR", str(tmp_path / "keys"))
    whys = [Verifier(None, "alpha").check("arm", _sign(1, T0), b""),
            Verifier(KEY, "alpha").check("arm", Signature(0, 0, bytes(32)), b"")]
    for why in whys:
        assert why.startswith("arm: refused") and "/" not in why and ".key" not in why, why
    assert replay_path("alpha") == tmp_path / "keys" / "alpha.replay"


_RELAYS = st.sampled_from(["arm", "disarm", "reset", "recorder/stop", "controller/setpoint"])


@given(relay=_RELAYS, link=st.integers(0, 255), offset=st.integers(-STALE_LIMIT, AHEAD_LIMIT),
       payload=st.binary(max_size=40), data=st.data())
def test_property_any_change_to_any_field_of_a_signed_request_is_refused(relay, link, offset, payload, data):
    ts = T0 + offset
    sig = _sign(link, ts, relay, payload)
    field = data.draw(st.sampled_from(["relay", "link", "timestamp", "payload", "mac"]))
    new_relay, new_sig, new_payload = relay, sig, payload
    if field == "relay":
        new_relay = data.draw(_RELAYS.filter(lambda r: r != relay))
    elif field == "link":
        new_sig = Signature(data.draw(st.integers(-1000, 1000).filter(lambda v: v != link)), ts, sig.mac)
    elif field == "timestamp":
        new_ts = data.draw(st.one_of(st.integers(1, 1 << 16).map(lambda k: ts + k * (1 << 48)),
                                     st.integers(-(1 << 60), 1 << 60)).filter(lambda v: v != ts))
        new_sig = Signature(link, new_ts, sig.mac)
    elif field == "payload":
        new_payload = data.draw(st.binary(max_size=40).filter(lambda p: p != payload))
    else:
        new_sig = Signature(link, ts, data.draw(st.binary(min_size=1, max_size=40).filter(lambda m: m != sig.mac)))
    fresh = Verifier(KEY, "alpha", now=lambda: T0)
    assert fresh.check(new_relay, new_sig, new_payload) is not None  # before the original was seen
    seen = Verifier(KEY, "alpha", now=lambda: T0)
    assert seen.check(relay, sig, payload) is None
    assert seen.check(new_relay, new_sig, new_payload) is not None  # and after
    assert seen.check(relay, sig, payload) is not None and seen.counts["accepted"] == 1


_REQUESTS = st.lists(st.tuples(st.integers(0, 300 * 100_000),  # the vehicle clock moves on by this first
                               st.integers(-1, 256), st.integers(-(1 << 50), 1 << 50),  # link, ts - now
                               st.booleans(), st.booleans()),  # signed with the key? an exact copy of the previous?
                     max_size=30)


@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(requests=_REQUESTS, link=st.integers(0, 255), restart=st.booleans())
def test_property_no_request_sequence_locks_out_a_correctly_clocked_operator(requests, link, restart):
    """From anyone: a stranger (no key), a key holder with any clock, copies; then the operator, on any link id,
    with the vehicle's time, is accepted (across a restart too)."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        clock = [T0]
        state = Path(folder) / "alpha.replay"
        verifier = Verifier(KEY, "alpha", now=lambda: clock[0], state=state)
        previous = Signature(0, 0, bytes(32))
        for step, req_link, delta, keyed, copy in requests:
            clock[0] += step
            ts = clock[0] + delta
            sig = previous if copy else Signature(req_link, ts, mac(KEY if keyed else OTHER, "alpha", "arm",
                                                                   req_link & 0xFF, ts & TIMESTAMP_MAX, b"other"))
            verifier.check("arm", sig, b"other")
            previous = sig
        if restart:
            verifier = Verifier(KEY, "alpha", now=lambda: clock[0], state=state)
        assert verifier.check("arm", _sign(link, clock[0], payload=b"operator"), b"operator") is None


@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(requests=st.lists(st.tuples(st.integers(0, 100 * 100_000), st.integers(0, 255),
                                   st.integers(-STALE_LIMIT, AHEAD_LIMIT)), min_size=1, max_size=20),
       back=st.integers(0, 1 << 40), ahead=st.integers(0, 1 << 40))
def test_property_a_restart_refuses_every_request_accepted_before_it(requests, back, ahead):
    """Whatever the vehicle's clock after the restart (behind: no real-time clock; or ahead)."""
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        clock = [T0]
        state = Path(folder) / "alpha.replay"
        verifier = Verifier(KEY, "alpha", now=lambda: clock[0], state=state)
        accepted = []
        for step, link, delta in requests:
            clock[0] += step
            sig = _sign(link, clock[0] + delta)
            if verifier.check("arm", sig, b"") is None:
                accepted.append(sig)
        assert accepted
        for now in (clock[0], max(0, clock[0] - back), clock[0] + ahead):
            restarted = Verifier(KEY, "alpha", now=lambda now=now: now, state=state)
            assert all(restarted.check("arm", sig, b"") is not None for sig in accepted)


def test_without_a_key_on_the_vehicle_every_operator_request_is_refused():
    verifier = Verifier(None, "alpha")
    why = verifier.check("arm", Signer(KEY, "alpha").sign("arm", b""), b"")
    assert why.startswith("arm: refused: no operator key on the vehicle") and verifier.counts["no_key"] == 1


def test_a_signer_signs_rising_timestamps_even_within_one_clock_tick():
    signer = Signer(KEY, "alpha")
    stamps = [signer.sign("arm", b"").timestamp for _ in range(100)]
    assert stamps == sorted(set(stamps)) and 0 < stamps[0] < 1 << 48


def test_a_signed_message_carries_its_signature_and_any_change_breaks_it():
    from hindrax_msgs.msg import ControlSetpoint

    msg = ControlSetpoint(vertical_mode=ControlSetpoint.VERTICAL_DEPTH, depth_m=1.0)
    Signer(KEY, "alpha").sign_message("controller/setpoint", msg)
    assert any(msg.signature.mac) and msg.signature.timestamp > 0
    assert Verifier(KEY, "alpha").check_message("controller/setpoint", msg) is None
    msg.depth_m = 1.4
    assert Verifier(KEY, "alpha").check_message("controller/setpoint", msg).startswith("controller/setpoint: refused")
    assert signed_payload(msg) == signed_payload(ControlSetpoint(vertical_mode=1, depth_m=1.4))
    assert b"depth_m=" + (1.4).hex().encode() in signed_payload(msg) and b"signature" not in signed_payload(msg)


def test_the_key_file_is_created_0600_and_loaded(tmp_path, monkeypatch):
    monkeypatch.setenv("HINDRAX_KEYS_DIR", str(tmp_path / "keys"))
    path = create_key(key_path("alpha"))
    assert path == tmp_path / "keys" / "alpha.key"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert len(load_key(path)) == KEY_BYTES
    with pytest.raises(OperatorKeyError, match="exists"):
        create_key(path)
    assert create_key(path, force=True) == path


def test_a_key_others_can_read_or_a_malformed_one_is_refused_in_one_line(tmp_path):
    path = tmp_path / "alpha.key"
    path.write_text(KEY.hex() + "\n")
    os.chmod(path, 0o644)
    with pytest.raises(OperatorKeyError, match="mode 0644 lets others read it: chmod 600"):
        load_key(path)
    os.chmod(path, 0o600)
    assert load_key(path) == KEY
    path.write_text("abc\n")
    with pytest.raises(OperatorKeyError, match="not 64 hex digits"):
        load_key(path)
    with pytest.raises(OperatorKeyError, match="hindrax keys"):
        load_key(tmp_path / "missing.key")
