#!/usr/bin/env bash
# /usr/local/bin/hindrax in the image: `docker exec hindrax hindrax ...` and the HEALTHCHECK (which Docker runs
# without the entry point) run the installed command with the container's ROS environment (ROS, workspace,
# discovery range, domain, and for `hindrax health` the launch the container runs), set up by the entry point.
exec "${HINDRAX_ENTRYPOINT:-/entrypoint.sh}" "${HINDRAX_COMMAND:-/ws/install/lib/hindrax_ident/hindrax}" "$@"
