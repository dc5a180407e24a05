#!/usr/bin/env bash
# /usr/local/bin/hindrax in the image: `docker exec hindrax hindrax ...` runs the installed command with the
# container's ROS environment (ROS, workspace, discovery range, domain), set up by the entry point.
exec "${HINDRAX_ENTRYPOINT:-/entrypoint.sh}" "${HINDRAX_COMMAND:-/ws/install/lib/hindrax_ident/hindrax}" "$@"
