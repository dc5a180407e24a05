#!/usr/bin/env bash
# Build the image with this host's device group IDs and user ID, found here at build time (the image's user must be in
# the groups that own /dev/ttyUSB*, /dev/i2c-1 and /dev/gpiochip* on this Pi, whose IDs differ between OS images).
#   cd /opt/hindrax && docker/build.sh [more docker compose build options]
# HINDRAX_ENV (default /etc/hindrax/hindrax.env) gives the other settings; the IDs found here override any there.
set -euo pipefail
cd "$(dirname "$0")/.."
gid() {
  local id
  id=$(getent group "$1" | cut -d: -f3)
  [ -n "$id" ] || { echo "docker/build.sh: no group $1 on this host: sudo groupadd --system $1 (docs/deployment.md §2)" >&2; exit 1; }
  echo "$id"
}
DIALOUT_GID=$(gid dialout)
I2C_GID=$(gid i2c)
GPIO_GID=$(gid gpio)
HINDRAX_UID=${HINDRAX_UID:-$(id -u hindrax 2>/dev/null || echo 1000)}
export DIALOUT_GID I2C_GID GPIO_GID HINDRAX_UID
echo "docker/build.sh: uid $HINDRAX_UID, groups dialout $DIALOUT_GID, i2c $I2C_GID, gpio $GPIO_GID"
exec docker compose --env-file "${HINDRAX_ENV:-/etc/hindrax/hindrax.env}" -f docker/compose.yaml build "$@"
