#!/usr/bin/env bash
# /usr/local/bin/hindrax in the image: `docker exec hindrax hindrax ...` and the HEALTHCHECK (which Docker runs
# without the entry point) run the installed command with the container's ROS environment (ROS, workspace,
# discovery range, domain, and for `hindrax health` the launch the container runs), set up by the entry point.
# The command is hindrax_onboard's (the vehicle's commands; the topside's answer that they run on the topside PC).
exec "${HINDRAX_ENTRYPOINT:-/entrypoint.sh}" "${HINDRAX_COMMAND:-/ws/install/lib/hindrax_onboard/hindrax}" "$@"
