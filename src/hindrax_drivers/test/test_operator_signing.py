"""Signed operator commands (hindrax_drivers.gateway.operator_signing): MAVLink-2-style HMAC-SHA256 with a 32-byte key,
a 48-bit timestamp rising per link, a link id. Unsigned, wrong-key, replayed and re-targeted requests are refused with
one line and counted; the key file is created with mode 0600 and refused when others can read it."""
from __future__ import annotations

import hmac
import os
import stat
from hashlib import sha256

import pytest

from hindrax_drivers.gateway.operator_signing import (KEY_BYTES, NEW_LINK_WINDOW, OperatorKeyError, Signature, Signer,
                                                      Verifier, create_key, key_path, load_key, mac, signed_payload)

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
    assert verifier.counts == {"accepted": 0, "unsigned": 1, "bad_signature": 4, "replayed": 0, "no_key": 0}


def test_timestamps_must_rise_per_link_and_a_new_link_may_not_start_far_in_the_past():
    verifier = Verifier(KEY, "alpha", now=lambda: 0)
    sign = lambda link, ts: Signature(link, ts, mac(KEY, "alpha", "arm", link, ts, b""))  # noqa: E731
    assert verifier.check("arm", sign(1, 10 * NEW_LINK_WINDOW), b"") is None
    assert verifier.check("arm", sign(1, 10 * NEW_LINK_WINDOW - 1), b"") is not None  # older on the same link
    assert verifier.check("arm", sign(2, 9 * NEW_LINK_WINDOW - 1), b"") is not None  # a new link, > 60 s older
    assert verifier.check("arm", sign(2, 9 * NEW_LINK_WINDOW + 1), b"") is None  # a new link within 60 s
    assert verifier.counts["replayed"] == 2


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


def test_a_recorded_request_replayed_after_a_gateway_restart_is_stale_by_the_vehicle_clock():
    """A restarted gateway has no links yet: a new link's first timestamp must be within 60 s of the vehicle's
    clock, so an arm captured earlier cannot be replayed then."""
    sig = Signer(KEY, "alpha").sign("arm", b"")
    assert Verifier(KEY, "alpha").check("arm", sig, b"") is None  # fresh: accepted by a new gateway
    later = Verifier(KEY, "alpha", now=lambda: sig.timestamp + NEW_LINK_WINDOW + 1)  # restarted 60 s later
    assert later.check("arm", sig, b"").startswith("arm: refused: replayed or stale")
