"""``hindrax sros2 policy|keystore``: the SROS2 permissions of the vehicle (docs/deployment.md, "SROS2 on the Pi").

``hindrax sros2 policy [--config FILE] [--out DIR]`` writes ``internal.policy.xml`` and ``topside.policy.xml``
(:mod:`hindrax_bringup.gateway.sros2_policy`) for the vehicle file's ``vehicle.name`` and the enclaves of the installed
launch files (``vehicle.launch.xml``, ``pool_test.launch.xml``). Runs anywhere (no sros2 needed).

``hindrax sros2 keystore KEYSTORE [--config FILE] [--internal-domain-id N] [--topside-domain-id N]`` creates the
keystore on the vehicle (or adds to it): the two policies under ``KEYSTORE/policies/``, then sros2's own artifact
generation (``ros2 security generate_artifacts``' Python API: certificate authority, one key, certificate and signed
permissions per enclave), the internal enclaves' permissions for the internal domain, the topside ones for the topside
domain; then the vehicle's governance (:func:`hindrax_bringup.gateway.sros2_policy.governance`: participants without a
certificate may call the e-stop on the topside, nothing else) replaces sros2's default one, signed with the keystore's
permissions CA. Needs sros2 (``ros-jazzy-sros2`` from apt, on the Pi); without it, exit 1 with one line saying so.
Exit 1 with one line for an invalid vehicle file or launch file."""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from .common import CommandError, add_config_argument, load_vehicle

__all__ = ["add_arguments", "run", "write_policies"]

#: the launch files whose processes get an internal enclave: PACKAGE/FILE
LAUNCH_FILES = ("hindrax_bringup/vehicle.launch.xml", "hindrax_onboard/pool_test.launch.xml")
#: what the missing sros2 package means, and where it comes from
NO_SROS2 = ("sros2 is not installed: on the Pi, `sudo apt install ros-jazzy-sros2` (the development machines' ROS 2 "
            "wheels have no sros2 and no DDS Security); `hindrax sros2 policy` writes the policy files without it")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    add_config_argument(parser)
    if parser.prog.endswith("keystore"):
        parser.add_argument("keystore", help="keystore directory (ROS_SECURITY_KEYSTORE on the vehicle)")
        parser.add_argument("--internal-domain-id", type=int, default=None, metavar="N",
                            help="the vehicle's internal domain (default ROS_DOMAIN_ID, else 0)")
        parser.add_argument("--topside-domain-id", type=int, default=0, metavar="N",
                            help="the topside domain the gateway joins (the launch argument topside_domain_id; "
                                 "default 0)")
    else:
        parser.add_argument("--out", default=".", metavar="DIR", help="folder for the two policy files (default .)")


def _enclaves() -> dict[str, tuple[str, ...]]:
    from hindrax_bringup.layout.launch_xml import LaunchFileError, ament_share, read_launch
    from hindrax_bringup.gateway.sros2_policy import launch_enclaves

    out: dict[str, set] = {}
    for spec in LAUNCH_FILES:
        package, _, name = spec.partition("/")
        try:
            processes = read_launch(ament_share(package) / "launch" / name, {"record": "true", "controller": "true"}
                                    if package == "hindrax_bringup" else {})
            found = launch_enclaves(processes)
        except (LaunchFileError, ValueError) as exc:
            raise CommandError(f"hindrax sros2: {exc}") from exc
        for enclave, nodes in found.items():
            out.setdefault(enclave, set()).update(nodes)
    return {k: tuple(sorted(v)) for k, v in sorted(out.items())}


def write_policies(config: str | None, out: Path) -> dict[str, Path]:
    """Write ``internal.policy.xml`` and ``topside.policy.xml`` into ``out``; returns {domain: path}. Raises
    :class:`CommandError` (one line) for an invalid vehicle or launch file."""
    from hindrax_bringup.gateway.sros2_policy import internal_policy, topside_policy

    cfg = load_vehicle(config)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"internal": out / "internal.policy.xml", "topside": out / "topside.policy.xml"}
    paths["internal"].write_text(internal_policy(_enclaves()))
    paths["topside"].write_text(topside_policy(cfg.vehicle.name))
    return paths


def write_governance(keystore: Path, vehicle_name: str, internal_domain: int, topside_domain: int) -> Path:
    """Write the vehicle's governance into ``keystore/enclaves/governance.xml`` and sign it (S/MIME, the permissions
    CA) into ``governance.p7s``, the file every enclave's ``governance.p7s`` links to. Needs sros2."""
    from sros2._utilities import create_smime_signed_file

    from hindrax_bringup.gateway.sros2_policy import governance

    try:
        text = governance(vehicle_name, internal_domain, topside_domain)
    except ValueError as exc:
        raise CommandError(f"hindrax sros2 keystore: {exc}") from None
    enclaves = keystore / "enclaves"
    (enclaves / "governance.xml").write_text(text)
    create_smime_signed_file(keystore / "public" / "permissions_ca.cert.pem",
                             keystore / "private" / "permissions_ca.key.pem",
                             enclaves / "governance.xml", enclaves / "governance.p7s")
    print(f"governance: {enclaves / 'governance.p7s'} (the e-stop open to participants without a certificate)")
    return enclaves / "governance.p7s"


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    if not hasattr(args, "keystore"):
        for domain, path in write_policies(args.config, Path(args.out)).items():
            print(f"{domain}: {path}")
        return 0
    try:
        from sros2.api._artifact_generation import generate_artifacts
    except ImportError as exc:
        raise CommandError(f"hindrax sros2 keystore: {NO_SROS2}") from exc
    keystore = Path(args.keystore)
    paths = write_policies(args.config, keystore / "policies")
    internal_domain = args.internal_domain_id if args.internal_domain_id is not None else \
        int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    saved = os.environ.get("ROS_DOMAIN_ID")
    try:  # sros2 writes ROS_DOMAIN_ID into each grant it generates
        for domain, domain_id in (("internal", internal_domain), ("topside", args.topside_domain_id)):
            os.environ["ROS_DOMAIN_ID"] = str(domain_id)
            generate_artifacts(keystore, [], [paths[domain]])
            print(f"{domain} enclaves (domain {domain_id}): permissions from {paths[domain]}")
    finally:
        if saved is None:
            os.environ.pop("ROS_DOMAIN_ID", None)
        else:
            os.environ["ROS_DOMAIN_ID"] = saved
    write_governance(keystore, load_vehicle(args.config).vehicle.name, internal_domain, args.topside_domain_id)
    print(f"keystore {keystore}: set ROS_SECURITY_KEYSTORE={keystore.resolve()} ROS_SECURITY_ENABLE=true "
          "ROS_SECURITY_STRATEGY=Enforce for the vehicle's processes")
    return 0
