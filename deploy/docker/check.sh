#!/usr/bin/env bash
# `make check-docker`: builds the image from the Dockerfile and checks it the
# way a deployment uses it — ready, a step, gRPC live, SIGHUP reload, SIGTERM exit 0
# within the grace period, a non-root uid — then prints the image size.
#
# With no image hub reachable (this project's machines), the base image is
# made from Debian's packages: debootstrap --variant=minbase bookworm, then
# docker import; the builder then takes the binaries built on this host (same
# Debian release) instead of compiling in a rust image. Containers use the
# host's network and loopback only. A docker daemon this script starts, it stops.
set -euo pipefail
cd "$(dirname "$0")/../.."

DOCKER=${DOCKER:-docker}
IMAGE=${IMAGE:-nuno:check}
BASE=${BASE:-nuno-base:bookworm}
PORT=${PORT:-18181}
GRPC_PORT=${GRPC_PORT:-18182}
GRACE_S=${GRACE_S:-10}
NAME=nuno-check-$$
started_daemon=""

log() { printf '== %s\n' "$*"; }
fail() { printf 'check-docker FAILED: %s\n' "$*" >&2; exit 1; }

cleanup() {
    $DOCKER rm -f "$NAME" >/dev/null 2>&1 || true
    if [ -n "$started_daemon" ]; then
        kill "$started_daemon" 2>/dev/null || true
        wait "$started_daemon" 2>/dev/null || true
    fi
}
trap cleanup EXIT

if ! $DOCKER info >/dev/null 2>&1; then
    command -v dockerd >/dev/null && [ "$(id -u)" = 0 ] \
        || fail "no docker daemon answers, and none can be started here (needs root and dockerd: apt-get install docker.io)"
    log "starting dockerd"
    dockerd >/tmp/nuno-check-dockerd.log 2>&1 &
    started_daemon=$!
    for _ in $(seq 60); do $DOCKER info >/dev/null 2>&1 && break; sleep 1; done
    $DOCKER info >/dev/null 2>&1 || fail "dockerd did not come up (/tmp/nuno-check-dockerd.log)"
fi

build_args=()
if timeout 60 $DOCKER pull -q debian:bookworm-slim >/dev/null 2>&1 \
    && timeout 60 $DOCKER pull -q rust:1.95-bookworm >/dev/null 2>&1; then
    log "image hub reachable: building from source in rust:1.95-bookworm"
    rm -rf .docker-dist
else
    if ! $DOCKER image inspect "$BASE" >/dev/null 2>&1; then
        command -v debootstrap >/dev/null || fail "no image hub and no debootstrap (apt-get install debootstrap)"
        rootfs=$(mktemp -d /tmp/nuno-rootfs.XXXXXX)
        log "no image hub: debootstrap bookworm into $rootfs"
        debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian >/tmp/nuno-check-debootstrap.log \
            || fail "debootstrap failed (/tmp/nuno-check-debootstrap.log)"
        tar -C "$rootfs" -c . | $DOCKER import - "$BASE" >/dev/null
        rm -rf "$rootfs"
    fi
    log "building the binaries on the host for the builder stage"
    make build >/dev/null
    target=${CARGO_TARGET_DIR:-target}
    rm -rf .docker-dist && mkdir -p .docker-dist
    cp "$target/release/nuno-server" "$target/release/nuno-trainer" .docker-dist/
    # Symbols stay (backtraces name functions); the line tables are 100 MB a binary.
    strip --strip-debug .docker-dist/nuno-server .docker-dist/nuno-trainer
    build_args=(--build-arg "BUILD_IMAGE=$BASE" --build-arg "RUNTIME_IMAGE=$BASE")
fi

log "docker build"
$DOCKER build --network host "${build_args[@]}" -t "$IMAGE" . >/tmp/nuno-check-build.log 2>&1 \
    || { tail -30 /tmp/nuno-check-build.log >&2; fail "docker build failed (/tmp/nuno-check-build.log)"; }
rm -rf .docker-dist

log "docker run (--network host, REST on 127.0.0.1:$PORT, gRPC on 127.0.0.1:$GRPC_PORT)"
$DOCKER run -d --name "$NAME" --network host --stop-timeout "$GRACE_S" "$IMAGE" \
    nuno-server --models /opt/nuno/models --addr "127.0.0.1:$PORT" --grpc-addr "127.0.0.1:$GRPC_PORT" >/dev/null
base="http://127.0.0.1:$PORT"
for _ in $(seq 60); do curl -fsS "$base/readyz" >/dev/null 2>&1 && break; sleep 1; done
curl -fsS "$base/readyz" | grep -q '"ready":true' || { $DOCKER logs "$NAME" >&2; fail "/readyz never answered ready"; }
log "ready"

model=$(curl -fsS "$base/v1/models" | python3 -c 'import json,sys; print(json.load(sys.stdin)["models"][0]["id"])')
dims=$(curl -fsS "$base/v1/models/$model" | python3 -c 'import json,sys; d=json.load(sys.stdin); print(d["obs_dim"], d["act_dim"])')
read -r obs act <<<"$dims"
body=$(python3 -c "import json; print(json.dumps({'states': [[0.0]*$obs]*2, 'actions': [[0.1]*$act]*2, 'particles': 3, 'seed': 1}))")
step=$(curl -fsS -H 'Content-Type: application/json' -d "$body" "$base/v1/models/$model/step")
python3 -c "
import json, sys
s = json.loads(sys.argv[1])
assert len(s['next_states']) == 2 and len(s['next_states'][0]) == 3 and len(s['next_states'][0][0]) == $obs, s
assert len(s['eta']) == 2
" "$step" || fail "the step answer has the wrong shape: $step"
log "step: 2 rows x 3 particles of $obs numbers, model $model"

# KServe's gRPC ServerLive, framed by hand (an empty request: five zero bytes); the
# answer is one frame holding ServerLiveResponse{live: true} = 08 01.
live=$(printf '\0\0\0\0\0' | curl -fsS --http2-prior-knowledge -H 'content-type: application/grpc' \
    -H 'te: trailers' --data-binary @- \
    "http://127.0.0.1:$GRPC_PORT/inference.GRPCInferenceService/ServerLive" | od -An -tx1 | tr -d ' \n')
[ "$live" = "00000000020801" ] || fail "gRPC ServerLive answered '$live', not live"
log "gRPC: ServerLive answers live"

uid=$($DOCKER exec "$NAME" id -u)
[ "$uid" != 0 ] || fail "the server runs as root"
log "runs as uid $uid"

$DOCKER kill -s HUP "$NAME" >/dev/null
for _ in $(seq 30); do $DOCKER logs "$NAME" 2>&1 | grep -q "SIGHUP: models reloaded" && break; sleep 1; done
$DOCKER logs "$NAME" 2>&1 | grep -q "SIGHUP: models reloaded" || fail "no reload logged after SIGHUP"
curl -fsS "$base/readyz" | grep -q '"ready":true' || fail "not ready after the reload"
log "SIGHUP reloaded the models"

start=$(date +%s.%N)
$DOCKER stop -t "$GRACE_S" "$NAME" >/dev/null
stopped=$(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.2f}')" "$start" "$(date +%s.%N)")
code=$($DOCKER inspect -f '{{.State.ExitCode}}' "$NAME")
[ "$code" = 0 ] || { $DOCKER logs "$NAME" >&2; fail "exit code $code after SIGTERM (137: killed after the ${GRACE_S} s grace period)"; }
log "SIGTERM: exit 0 after ${stopped} s (grace period ${GRACE_S} s)"

size=$($DOCKER image inspect -f '{{.Size}}' "$IMAGE")
log "image $IMAGE: $((size / 1000000)) MB"
echo "check-docker passed"
