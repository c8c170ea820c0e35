#!/usr/bin/env bash
# Issue 33's planning and batching figures on loopback with wrk:
# - batch-1 `step` requests/s and p99 at 1, 8 and 64 connections, and `score` at iCEM's
#   size at 8, with dynamic batching off (--batch-delay-us 0) and on (the default), one
#   server each;
# - `score` of 400 candidates x horizon 30 at 1 and 5 particles, binary both ways, on the
#   bodies `cargo bench --bench score` writes after measuring the same work in process
#   (the EM step at the same batch, and `score_sequences`), in the same run;
# - `plan` calls at PETS' hopper sizes (CEM) and iCEM's (iCEM), 20 particles.
# Needs `make venv` and a release build; results go to BENCHMARKS.md by hand.
PORT="${PORT:-18091}"
DURATION="${DURATION:-10s}"
source "$(dirname "$0")/server_common.sh"

url="http://127.0.0.1:$PORT/v1/models/hopper-random"
summary() { grep -E "Requests/sec|Non-2xx|Socket errors|requests in|^ +(50|99)%"; }
step_at() { # connections
  echo "== step batch 1 (binary), $1 connections, batch delay ${DELAY} µs"
  CONNECTIONS=$1 post_load "$DURATION" "$url/step" "$WORK/step-1.bin" application/octet-stream | summary
}
restart() { # batch delay in µs
  kill $SERVER; wait $SERVER 2>/dev/null || true
  DELAY=$1
  "${CARGO_TARGET_DIR:-target}/release/nuno-server" --models models --addr "127.0.0.1:$PORT" \
    --batch-delay-us "$1" 2>"$WORK/server.log" &
  SERVER=$!
  until curl -fs "http://127.0.0.1:$PORT/readyz" >/dev/null; do sleep 0.2; done
}
post_load() { # wrk needs a connection per thread
  wrk -t$(( CONNECTIONS < 2 ? 1 : 2 )) -c"$CONNECTIONS" -d"$1" --timeout 120s --latency -s benches/wrk_post.lua "$2" -- "$3" "$4" ${5:-}
}
echo "== in process, the same run (and the score bodies)"
NUNO_SCORE_BODIES="$WORK" cargo bench --bench score 2>/dev/null
export RUST_LOG=warn
for delay in 0 200; do
  restart $delay
  for c in 1 8 64; do step_at $c; done
  echo "== score 200 x 10 (iCEM's size), 1 particle (binary), 8 connections, batch delay ${DELAY} µs"
  CONNECTIONS=8 post_load "$DURATION" "$url/score" "$WORK/score-200x10-p1.bin" application/octet-stream application/octet-stream | summary
done
for p in 1 5; do
  echo "== score 400 x 30, $p particles (binary both ways), 1 connection"
  CONNECTIONS=1 post_load "$DURATION" "$url/score" "$WORK/score-400x30-p$p.bin" application/octet-stream application/octet-stream | summary
done
for name in icem pets; do
  echo "== plan, $name sizes: 3 calls"
  for i in 1 2 3; do
    curl -s -o /dev/null -w "%{time_total} s\n" "$url/plan" -H 'content-type: application/json' --data-binary @"$WORK/plan-$name.json"
  done
done
