#!/usr/bin/env bash
# Container entry point: source ROS 2 and the workspace, set DDS discovery for the tether, run the command.
#
# Environment (all optional):
#   HINDRAX_DISCOVERY_RANGE  LOCALHOST | SUBNET | SYSTEM_DEFAULT | OFF   (default SUBNET: the topside PC is on
#                            the tether's Ethernet subnet; use LOCALHOST for simulation and tests)
#   ROS_DOMAIN_ID            0-101 (default 0)
#   HINDRAX_CONFIG           vehicle configuration (default /ws/config/hindrax.yaml)
#   ROS_SETUP, WS_SETUP      setup scripts to source (defaults: /opt/ros/jazzy/setup.bash, /ws/install/setup.bash)
#   HINDRAX_RECORD           1 (default): the default bringup records every topic to recording.output_root
#                            (/ws/runs, a mounted folder); 0: no recording
# With no arguments it runs `hindrax bringup --config "$HINDRAX_CONFIG" --record`.
set -eo pipefail

range=${HINDRAX_DISCOVERY_RANGE:-SUBNET}
case "$range" in
  LOCALHOST|SUBNET|SYSTEM_DEFAULT|OFF) ;;
  *) echo "entrypoint: HINDRAX_DISCOVERY_RANGE=$range: allowed LOCALHOST, SUBNET, SYSTEM_DEFAULT, OFF" >&2; exit 2 ;;
esac
domain=${ROS_DOMAIN_ID:-0}
if ! [[ "$domain" =~ ^[0-9]+$ ]] || [ "$domain" -gt 101 ]; then
  echo "entrypoint: ROS_DOMAIN_ID=$domain: allowed integer 0-101" >&2
  exit 2
fi
export ROS_AUTOMATIC_DISCOVERY_RANGE="$range"
export ROS_DOMAIN_ID="$domain"
config=${HINDRAX_CONFIG:-/ws/config/hindrax.yaml}
export HINDRAX_CONFIG="$config"

set +u
# shellcheck disable=SC1090
source "${ROS_SETUP:-/opt/ros/jazzy/setup.bash}"
# shellcheck disable=SC1090
source "${WS_SETUP:-/ws/install/setup.bash}"
# colcon installs ament_python console scripts in lib/<package> (the `ros2 run` location), not on PATH.
export PATH="${HINDRAX_BIN_DIR:-/ws/install/lib/hindrax_ident}:$PATH"

if [ "$#" -eq 0 ]; then
  set -- hindrax bringup
fi
if [ "$1" = "hindrax" ] && [ "${2:-}" = "bringup" ] && [[ " $* " != *" --config "* ]]; then
  set -- "$@" --config "$config"
fi
if [ "$1" = "hindrax" ] && [ "${2:-}" = "bringup" ] && [ "${HINDRAX_RECORD:-1}" = "1" ] \
   && [[ " $* " != *" --record "* ]] && [[ " $* " != *" --sim "* ]]; then
  set -- "$@" --record
fi
exec "$@"
