#!/usr/bin/env bash
# Load benchmark of nuno-server on loopback with wrk (Debian package `wrk`):
# step at batch 1, 256 and 4096 with JSON and binary (safetensors) bodies, and a
# closed-loop rollout of 4096 starts x 10 steps (JSON, and with a binary answer). Needs `make venv` (numpy,
# safetensors) and a release build; results go to BENCHMARKS.md by hand.
PORT="${PORT:-18090}"
DURATION="${DURATION:-15s}"
source "$(dirname "$0")/server_common.sh"

url="http://127.0.0.1:$PORT/v1/models/hopper-random"
run() { # name, path, body file, content type[, accept]
  echo "== $1"
  post_load "$DURATION" "$url/$2" "$3" "$4" ${5:-} \
    | grep -E "Requests/sec|Non-2xx|Socket errors|requests in|^ +(50|99)%"
}
for n in 1 256 4096; do
  run "step batch $n, JSON" step "$WORK/step-$n.json" application/json
  run "step batch $n, binary" step "$WORK/step-$n.bin" application/octet-stream
done
run "rollout 4096 x h 10 (policy), JSON" rollout "$WORK/rollout-4096.json" application/json
run "rollout 4096 x h 10 (policy), JSON in, binary answer" rollout "$WORK/rollout-4096.json" application/json application/octet-stream
