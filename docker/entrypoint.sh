#!/usr/bin/env bash
# The vehicle's start: source ROS 2 and the workspace, set DDS discovery and the domain for the tether, then run
# the launch layout (one process per node, respawned; docs/deployment.md §1) or the command given.
# The Docker image's ENTRYPOINT, and the bare-metal systemd unit's ExecStart (docker/hindrax-bare-metal.service):
# one vehicle path, whichever way the Pi runs it.
#
# Environment (all optional except ROS_DOMAIN_ID for the vehicle launch):
#   ROS_DOMAIN_ID            the topside domain, 1-101: the one the vehicle's gateway joins and the topside PC uses
#                            (0, the ROS default that every other machine uses, is refused); docs/architecture.md §8.2
#   HINDRAX_DISCOVERY_RANGE  the gateway's topside range: LOCALHOST | SUBNET | SYSTEM_DEFAULT | OFF  (default SUBNET:
#                            the topside PC is on the tether's Ethernet subnet; ROS_STATIC_PEERS=<topside IP> as well)
#   HINDRAX_INTERNAL_DOMAIN_ID  the vehicle's internal domain, 0-101 (default 0): its own processes, and every
#                            command run here, on loopback only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)
#   HINDRAX_LAUNCH           "<package> <launch file>" (default "hindrax_bringup vehicle.launch.xml"; a pool campaign:
#                            "hindrax_onboard pool_test.launch.xml")
#   HINDRAX_RECORD           1 (default): record every topic; 0: no recording
#   HINDRAX_RUNS_DIR         root folder of the bags, a new timestamped bag per start (default /var/lib/hindrax/runs)
#   HINDRAX_CONFIG           a vehicle file to use instead of the installed one (a mounted file); must exist
#   HINDRAX_SROS2            1 (default): DDS Security (SROS2) on, Enforce, the keystore must exist; 0: off (a bench)
#   HINDRAX_KEYSTORE         the SROS2 keystore (default /etc/hindrax/keystore: `hindrax sros2 keystore DIR`); the
#                            launch gives each process its enclave, commands run here get /vehicle/tools
#   HINDRAX_KEYS_DIR         the operator key's folder (default /etc/hindrax/keys: `hindrax keys`); without the key
#                            the gateway refuses every operator request (the e-stop still works)
#   ROS_SETUP, WS_SETUP      setup scripts to source (defaults: /opt/ros/jazzy/setup.bash, /ws/install/setup.bash)
# With no arguments: ros2 launch $HINDRAX_LAUNCH [config:=$HINDRAX_CONFIG] record:=true|false output_dir:=$HINDRAX_RUNS_DIR
# `hindrax health` without --launch checks that same launch, with those arguments (the container's HEALTHCHECK).
set -eo pipefail

die() { echo "entrypoint: $*" >&2; exit 2; }

range=${HINDRAX_DISCOVERY_RANGE:-SUBNET}
case "$range" in
  LOCALHOST|SUBNET|SYSTEM_DEFAULT|OFF) ;;
  *) die "HINDRAX_DISCOVERY_RANGE=$range: allowed LOCALHOST, SUBNET, SYSTEM_DEFAULT, OFF" ;;
esac
[ -n "${ROS_STATIC_PEERS:-}" ] || unset ROS_STATIC_PEERS  # compose passes an empty one when none is set
if [ -n "${ROS_DOMAIN_ID:-}" ]; then
  if ! [[ "$ROS_DOMAIN_ID" =~ ^[0-9]+$ ]] || [ "$ROS_DOMAIN_ID" -gt 101 ]; then
    die "ROS_DOMAIN_ID=$ROS_DOMAIN_ID: allowed integer 1-101 (this vehicle's topside domain)"
  fi
fi
topside_domain=${ROS_DOMAIN_ID:-}
internal_domain=${HINDRAX_INTERNAL_DOMAIN_ID:-0}
if ! [[ "$internal_domain" =~ ^[0-9]+$ ]] || [ "$internal_domain" -gt 101 ] \
   || { [ "${topside_domain:-0}" != 0 ] && [ "$internal_domain" -eq "$topside_domain" ]; }; then
  die "HINDRAX_INTERNAL_DOMAIN_ID=$internal_domain: allowed integer 0-101, not the topside domain ROS_DOMAIN_ID"
fi
# The vehicle's processes and every command run here: the internal graph, loopback only (docs/architecture.md §8.2).
export ROS_DOMAIN_ID="$internal_domain" ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
if [ -n "${HINDRAX_CONFIG:-}" ]; then
  [ -f "$HINDRAX_CONFIG" ] || die "HINDRAX_CONFIG=$HINDRAX_CONFIG: no such file (mount it, or unset it for the installed vehicle file)"
  export HINDRAX_CONFIG
else
  unset HINDRAX_CONFIG  # commands and the launch file use the installed vehicle file
fi
export HINDRAX_KEYS_DIR=${HINDRAX_KEYS_DIR:-/etc/hindrax/keys}
case "${HINDRAX_SROS2:-1}" in
  1) keystore=${HINDRAX_KEYSTORE:-/etc/hindrax/keystore}
     [ -d "$keystore/enclaves" ] || die "HINDRAX_KEYSTORE=$keystore: no SROS2 keystore (create it with \`hindrax sros2 keystore $keystore\`; HINDRAX_SROS2=0 runs without DDS Security)"
     export ROS_SECURITY_KEYSTORE="$keystore" ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce ;;
  0) unset ROS_SECURITY_KEYSTORE ROS_SECURITY_ENABLE ROS_SECURITY_STRATEGY ;;
  *) die "HINDRAX_SROS2=$HINDRAX_SROS2: allowed 1 or 0" ;;
esac
case "${HINDRAX_RECORD:-1}" in
  1) record=true ;;
  0) record=false ;;
  *) die "HINDRAX_RECORD=$HINDRAX_RECORD: allowed 1 or 0" ;;
esac
runs=${HINDRAX_RUNS_DIR:-/var/lib/hindrax/runs}
read -r launch_pkg launch_file <<< "${HINDRAX_LAUNCH:-hindrax_bringup vehicle.launch.xml}"
[ -n "$launch_file" ] || die "HINDRAX_LAUNCH=$HINDRAX_LAUNCH: expected \"<package> <file>.launch.xml\""
launch_args=()
[ -n "${HINDRAX_CONFIG:-}" ] && launch_args+=("config:=$HINDRAX_CONFIG")
launch_args+=("record:=$record" "output_dir:=$runs")
[ -n "$topside_domain" ] && launch_args+=("topside_domain_id:=$topside_domain" "topside_discovery_range:=$range")

set +u
# shellcheck disable=SC1090
source "${ROS_SETUP:-/opt/ros/jazzy/setup.bash}"
# shellcheck disable=SC1090
source "${WS_SETUP:-/ws/install/setup.bash}"
set -u

if [ "$#" -eq 0 ]; then
  if [ -z "$topside_domain" ] || [ "$topside_domain" -eq 0 ]; then
    die "ROS_DOMAIN_ID=${topside_domain:-unset}: set this vehicle's own domain (1-101) in /etc/hindrax/hindrax.env; 0 is every other ROS machine's on the pool network"
  fi
  if [ "$record" = true ]; then
    mkdir -p "$runs" 2>/dev/null || true
    [ -w "$runs" ] || die "HINDRAX_RUNS_DIR=$runs is not writable by $(id -un) (uid $(id -u)): chown it on the host"
  fi
  echo "entrypoint: ros2 launch $launch_pkg $launch_file ${launch_args[*]} (internal domain $internal_domain on loopback; gateway: topside domain $topside_domain, discovery $range)" >&2
  exec ros2 launch "$launch_pkg" "$launch_file" "${launch_args[@]}"
fi
# a command run here joins the internal graph with the tools' enclave (the launch gives each process its own)
[ "${ROS_SECURITY_ENABLE:-}" = true ] && export ROS_SECURITY_ENCLAVE_OVERRIDE=/vehicle/tools
if [ "$(basename "$1")" = "hindrax" ] && [ "${2:-}" = "health" ] && [[ " $* " != *" --launch "* ]]; then
  set -- "$@" --launch "$launch_pkg/$launch_file" "${launch_args[@]}"
fi
exec "$@"
