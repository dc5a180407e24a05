"""The vertical thrust's saturation as a candidate term, chosen by cross-validation like the other
cross-channel inputs.

The bag is written here: a pilot's heave commands (geometry_msgs/WrenchStamped, held steps up to +-110 N, 20 Hz)
through the vehicle file's own thrust allocation (:class:`~hindrax_bringup.allocation.core.AllocationCore`, which
clips heave at its vertical thrusters' limits, about 62 N) into ``allocation/status`` (requested and achieved
wrench, as the allocation node publishes it). The vehicle moves under the ACHIEVED force: its heave truth of the
vehicle file (rigid + added inertia, quadratic and linear damping per direction, net buoyancy) driven through the
first-order thrust lag ``thrusters.time_constant_s``, integrated at 1 ms; nav_msgs/Odometry at 10 Hz with 1 cm/s
white noise. The estimator's model differs from that truth (one damping law chosen by cross-validation, its own
delay and lag search, a 20 Hz grid). Without the term the fit sees a command that goes on rising while the vehicle
does not; with it the force is the command plus a gain times the allocation's shortfall, and the gain is 1 by
construction here."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_fit.assessment import pipeline, results
from hindrax_fit.bag_input import any_topics
from hindrax_onboard.identification.model.dof_model import truth_parameters

T0_NS = 1_000_000_000_000


def _stamp(msg, t_ns: int):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
    return msg


def write_heave_bag(path, cfg, steps, seconds: float, top_n: float, seed: int = 2) -> None:
    """The bag of the module docstring: heave command steps uniform in +-``top_n`` N (FLU, up positive), held
    1-4 s (``steps``: the ``synthetic_runs`` fixture's)."""
    from geometry_msgs.msg import Wrench, WrenchStamped
    from nav_msgs.msg import Odometry
    from rclpy.serialization import serialize_message

    from hindrax_bringup.recording.writer import BagWriter, WriterOptions
    from hindrax_msgs.msg import AllocationStatus

    rng = np.random.default_rng(seed)
    alloc = AllocationCore(cfg)
    truth = truth_parameters(cfg, "heave")
    m, tau = truth["inertia"], float(cfg.thrusters.time_constant_s)
    kq = (truth["quadratic_damping_positive"], truth["quadratic_damping_negative"])
    kl = (truth["linear_damping_positive"], truth["linear_damping_negative"])
    n20 = int(seconds * 20)
    cmd = steps(rng, n20, -top_n, top_n)
    achieved = {}
    for c in np.unique(cmd):
        achieved[c] = float(alloc.allocate([0.0, 0.0, c, 0.0, 0.0, 0.0]).achieved_wrench_flu[2])
    w, f_lag, dt = 0.0, 0.0, 0.001  # FRD: w > 0 down; the force on the body is -(FLU z)
    with BagWriter(path, WriterOptions(fsync=False)) as bw:
        bw.add_topic("/wrench", "geometry_msgs/msg/WrenchStamped")
        bw.add_topic("/allocation/status", "hindrax_msgs/msg/AllocationStatus")
        bw.add_topic("/odom", "nav_msgs/msg/Odometry")
        for j in range(n20 * 50):
            t_ns = T0_NS + j * 1_000_000
            k20 = j // 50
            if j % 50 == 0:
                c = float(cmd[k20])
                wm = _stamp(WrenchStamped(), t_ns)
                wm.header.frame_id = "base_link"
                wm.wrench.force.z = c
                bw.write("/wrench", t_ns, serialize_message(wm))
                st = _stamp(AllocationStatus(), t_ns)
                st.header.frame_id = "base_link"
                st.requested_wrench = Wrench()
                st.requested_wrench.force.z = c
                st.achieved_wrench = Wrench()
                st.achieved_wrench.force.z = achieved[cmd[k20]]
                st.saturated = abs(achieved[cmd[k20]] - c) > 1e-6
                bw.write("/allocation/status", t_ns, serialize_message(st))
            if j % 100 == 0:
                od = _stamp(Odometry(), t_ns)
                od.header.frame_id, od.child_frame_id = "odom", "base_link"
                od.pose.pose.orientation.w = 1.0
                od.twist.twist.linear.z = -w + 0.01 * float(rng.standard_normal())
                bw.write("/odom", t_ns, serialize_message(od))
            f = -achieved[cmd[k20]]
            f_lag = f + (f_lag - f) * math.exp(-dt / tau)
            d = 0 if w > 0 else 1
            w += dt * (f_lag - kq[d] * abs(w) * w - kl[d] * w - truth["bias"]) / m


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def test_heave_saturation_is_chosen_and_its_gain_is_the_allocations(tmp_path, cfg, synthetic_runs):
    bag = tmp_path / "piloted_heave"
    write_heave_bag(bag, cfg, synthetic_runs.steps, 240.0, 110.0)
    res = pipeline.fit_bags([bag], any_topics.TopicChoice(), None, ["heave"])
    r = res.dofs["heave"]
    assert r.status == "fitted", r.reason
    c = r.core
    assert c.terms.saturation, c.terms.label
    got = dict(zip(c.names, c.theta))
    assert abs(got["saturation_gain"] - 1.0) < 0.15, got
    truth = truth_parameters(cfg, "heave")
    assert abs(got["inertia"] - truth["inertia"]) < 0.2 * truth["inertia"], got
    # the term is what predicts heave: every candidate without it does worse in cross-validation
    without = [k for k in c.candidates if not k.terms.saturation]
    assert without and min(k.mse for k in without) > 1.5 * c.chosen.mse
    doc = results.build_document(res, None, [bag])["dofs"]["heave"]
    assert doc["terms"]["saturation"] is True and "allocation" in doc["terms_meaning"]["saturation"]
    assert doc["saturation_gain"]["unit"] == "1"
    assert "allocation/status" in res.preprocessing["bags"][0]["saturation"]


def test_no_saturation_candidate_while_the_allocation_delivers_the_command(tmp_path, cfg, synthetic_runs):
    """Commands within the vertical thrusters' limits: the allocation achieves them, the shortfall is rounding
    only, and the term is not offered (its gain would not be identifiable)."""
    bag = tmp_path / "within_limits"
    write_heave_bag(bag, cfg, synthetic_runs.steps, 40.0, 50.0)
    pre = any_topics.preprocess_bag(bag, any_topics.TopicChoice(), None, any_topics.FitOptions())
    rec = any_topics.dof_records([pre], ["heave"], any_topics.FitOptions())["heave"]
    assert all(ch.shortfall is not None for ch in rec.chunks)
    assert not rec.saturates
