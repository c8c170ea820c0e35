#!/usr/bin/env bash
# Load benchmark of nuno-server on loopback with wrk (Debian package `wrk`):
# step at batch 1, 256 and 4096 with JSON and binary (safetensors) bodies, and a
# closed-loop rollout of 4096 starts x 10 steps (JSON, and with a binary answer). Needs `make venv` (numpy,
# safetensors) and a release build; results go to BENCHMARKS.md by hand.
set -euo pipefail
cd "$(dirname "$0")/.."
PORT="${PORT:-18090}"
DURATION="${DURATION:-15s}"
CONNECTIONS="${CONNECTIONS:-4}"
BODIES="$(mktemp -d)"
trap 'kill "$SERVER" 2>/dev/null || true; rm -rf "$BODIES"' EXIT

.venv/bin/python benches/server_bodies.py "$BODIES"
"${CARGO_TARGET_DIR:-target}/release/nuno-server" --models models --addr "127.0.0.1:$PORT" 2>"$BODIES/server.log" &
SERVER=$!
until curl -fs "http://127.0.0.1:$PORT/readyz" >/dev/null; do sleep 0.2; done

url="http://127.0.0.1:$PORT/v1/models/hopper-random"
run() { # name, path, body file, content type[, accept]
  echo "== $1"
  wrk -t2 -c"$CONNECTIONS" -d"$DURATION" --timeout 120s --latency -s benches/wrk_post.lua "$url/$2" -- "$3" "$4" ${5:-} \
    | grep -E "Requests/sec|Non-2xx|Socket errors|requests in|^ +(50|99)%"
}
for n in 1 256 4096; do
  run "step batch $n, JSON" step "$BODIES/step-$n.json" application/json
  run "step batch $n, binary" step "$BODIES/step-$n.bin" application/octet-stream
done
run "rollout 4096 x h 10 (policy), JSON" rollout "$BODIES/rollout-4096.json" application/json
run "rollout 4096 x h 10 (policy), JSON in, binary answer" rollout "$BODIES/rollout-4096.json" application/json application/octet-stream
