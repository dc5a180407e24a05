"""Output guard, pure logic (no ROS, no clocks): when must the PCA9685 outputs be silenced from outside the ESC?

The guard is the second stop path of docs/architecture.md §8. It asserts (silences the outputs: /OE high, or the
chip's all-off and sleep registers where /OE is not wired) when any of these holds:

* the ESC's output state (``esc/heartbeat``, 25 Hz from its steady-clock tick) has not been heard for
  ``timeout_s``: the ESC process died or hangs, and the chip keeps its last widths on the wire;
* the ESC reports ``OUTPUT_UNKNOWN``: the chip cannot be written or read back (I2C fault);
* the supervisor's heartbeat (``supervisor/heartbeat``) has not been heard for ``timeout_s``, or says ERROR (a
  breach is latched);
* the guard itself cannot silence the outputs (its /OE line could not be requested or driven, or its last write of
  the chip's sleep registers failed): it must not say OK when it could not act, so the ESC refuses to arm and
  disarms on its ERROR heartbeat; the node retries and clears it on success;
* its /OE line would keep its level when freed (a Raspberry Pi kernel without ``strict_gpiod``), or the guard cannot
  tell: a killed guard would leave the outputs enabled, so the outputs are never released (the ESC refuses to arm);
* the hardware watchdog on /OE ran out while the guard meant to feed it (docs/watchdog.md: the guard was frozen or
  starved): thrust must come back only through a new arm request;
* either heartbeat cannot be trusted to be its sender's
  (:class:`~hindrax_common.node_support.liveness.HeartbeatIdentity`: a second publisher, a wrong node name, a sequence
  that goes back, a new boot while armed): a forged or replayed heartbeat must not keep the outputs on.

Once asserted it stays asserted (latched) until every cause is gone AND the ESC reports that it is disarmed with
neutral confirmed on the chip (``OUTPUT_NEUTRAL``, ``armed`` false): thrust can then only come back through a new
arm request. That report must come after the ESC acted on one of the guard's own ERROR beats published since the
last cause: each ESC beat echoes the newest guard beat it has handled (``guard_boot_id``, ``guard_seq``), and the ESC
disarms in the handler of any guard beat that is not OK, and cannot arm again before a guard OK beat, which is only
published after the release. So an ESC beat acknowledging ``guard_seq`` >= :attr:`GuardCore.cause_seq` reports a
state later than that disarm, whatever the delivery delays (a beat merely received after the last
cause may have been published before an arm and delivered late). It starts asserted: nothing is
released until a live ESC has acknowledged one of this guard's ERROR beats at neutral."""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["GuardCore", "OUTPUT_UNKNOWN", "OUTPUT_NEUTRAL", "OUTPUT_COMMANDING"]

# hindrax_msgs/ThrusterPwm output_state constants (kept here so the core needs no ROS import)
OUTPUT_UNKNOWN, OUTPUT_NEUTRAL, OUTPUT_COMMANDING = 0, 1, 2


@dataclass
class GuardCore:
    """The guard's decision (module docstring). Ages are supplied by the node (executor-alive steady time, s)."""

    timeout_s: float
    asserted: bool = True
    reason: str = "start-up: no ESC output state confirmed yet"
    esc_state: int | None = None
    esc_armed: bool = False
    supervisor_ok: bool = False
    supervisor_message: str = ""
    identity_fault: str = ""
    drive_fault: str = ""
    release_fault: str = ""
    stall: str = ""
    #: the guard beat the newest ESC beat acknowledges (its ``guard_seq``; 0: none of this guard's boot)
    esc_ack_seq: int = 0
    #: the sequence number of the guard beat that carried the last decision with a cause (the first beat, asserted
    #: at start-up, until a cause is seen); release needs an ESC acknowledgement of it or later (module docstring)
    cause_seq: int = 1

    def on_esc(self, output_state: int, armed: bool, ack_seq: int) -> None:
        """The ESC's ``esc/heartbeat``: output_state constant, armed flag, and the sequence number of the newest
        beat of this guard it has handled (0 when it echoes none, or another boot's)."""
        self.esc_state, self.esc_armed, self.esc_ack_seq = int(output_state), bool(armed), int(ack_seq)

    def on_supervisor(self, ok: bool, message: str) -> None:
        """The supervisor's heartbeat: ok (level OK) or the breach reason."""
        self.supervisor_ok, self.supervisor_message = bool(ok), message

    def on_identity(self, fault: str) -> None:
        """The heartbeats' identity check: '' (both trusted) or the first fault
        (:attr:`hindrax_common.node_support.liveness.HeartbeatIdentity.fault`)."""
        self.identity_fault = fault

    def on_drive(self, fault: str) -> None:
        """The node's last attempt to drive /OE or write the chip: '' (it worked) or why it failed."""
        self.drive_fault = fault

    def on_release(self, fault: str) -> None:
        """'' when the /OE line returns to its pull-up once freed, else why not or why that is not known
        (:meth:`hindrax_common.transport.gpio.GpiodLine.release_problem`)."""
        self.release_fault = fault

    def on_stall(self, reason: str) -> None:
        """'' or why the hardware watchdog cut the outputs behind the guard's back (its feed stopped: the guard was
        frozen or starved). A cause at the next :meth:`decide`, latched like any other."""
        self.stall = reason

    def causes(self, esc_age_s: float, supervisor_age_s: float) -> list[str]:
        """Every reason to silence the outputs now (empty: none)."""
        out = []
        if self.stall:
            out.append(self.stall)
        if self.drive_fault:
            out.append(f"guard cannot act: {self.drive_fault}")
        if self.release_fault:
            out.append(f"guard cannot trust its /OE line: {self.release_fault}")
        if self.identity_fault:
            out.append(f"heartbeat not trusted: {self.identity_fault}")
        if esc_age_s > self.timeout_s:
            out.append("ESC output state silent" + (f" for {esc_age_s:.2f} s" if esc_age_s < 1e9 else "") +
                       " (esc/heartbeat): ESC process dead or hung")
        elif self.esc_state == OUTPUT_UNKNOWN:
            out.append("ESC output state unknown: the PCA9685 cannot be written or read back (I2C fault)")
        if supervisor_age_s > self.timeout_s:
            out.append("no supervisor heartbeat" + (f" for {supervisor_age_s:.2f} s" if supervisor_age_s < 1e9 else "")
                       + " (supervisor/heartbeat): supervisor dead or hung")
        elif not self.supervisor_ok:
            out.append(f"supervisor tripped: {self.supervisor_message}")
        return out

    def decide(self, esc_age_s: float, supervisor_age_s: float, beat_seq: int) -> tuple[bool, bool]:
        """Update :attr:`asserted`/:attr:`reason`; ``beat_seq``: the sequence number of the guard beat that will carry
        this decision. Returns ``(asserted, changed)``."""
        was = self.asserted
        causes = self.causes(esc_age_s, supervisor_age_s)
        if causes:
            self.asserted, self.reason = True, causes[0]
            self.cause_seq = int(beat_seq)
        elif self.asserted:
            if self.esc_ack_seq >= self.cause_seq and self.esc_state == OUTPUT_NEUTRAL and not self.esc_armed:
                self.asserted, self.reason = False, ""
            else:
                self.reason = "cause cleared; waiting for the ESC to report disarmed at neutral"
        return self.asserted, self.asserted != was
