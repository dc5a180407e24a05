#!/usr/bin/env bash
# /usr/local/bin/hindrax in the image: `docker exec hindrax hindrax ...` and the HEALTHCHECK (which Docker runs
# without the entry point) run the installed command with the container's ROS environment (ROS, workspace,
# discovery range, domain, and for `hindrax health` the launch the container runs), set up by the entry point.
# Known gap (issue 75): hindrax_tools, which holds the command, is topside and not in the image's build; until the
# vehicle's commands (health, keys, config check, esc, sros2) have a home there, this path is missing in the image.
exec "${HINDRAX_ENTRYPOINT:-/entrypoint.sh}" "${HINDRAX_COMMAND:-/ws/install/lib/hindrax_tools/hindrax}" "$@"
