#!/bin/sh
# HEALTHCHECK: the gRPC health service (cloudcast.v1.CloudCast) of this container's replica.
[ -f /tmp/cloudcast-listen ] || exit 1
exec cloudcast-load --probe --server "$(cat /tmp/cloudcast-listen)" --connect-timeout 3
