#!/usr/bin/env bash
# Soak benchmark of nuno-server on loopback: wrk at saturation on one request
# shape (default: step, batch 256, safetensors both ways) for DURATION after a
# WARMUP, sampling the server's RSS every SAMPLE_S seconds. Prints wrk's
# totals and latency percentiles, the failed requests (non-2xx and socket
# errors), and the RSS after warm-up, at the end and at its highest.
# Needs `make venv` and a release build; results go to BENCHMARKS.md by hand.
PORT="${PORT:-18091}"
WARMUP="${WARMUP:-60s}"
DURATION="${DURATION:-10m}"
SAMPLE_S="${SAMPLE_S:-10}"
BATCH="${BATCH:-256}"
source "$(dirname "$0")/server_common.sh"
url="http://127.0.0.1:$PORT/v1/models/hopper-random/step"
load() { # duration
  post_load "$1" "$url" "$WORK/step-$BATCH.bin" application/octet-stream
}
rss_kb() { awk '/^VmRSS/ {print $2}' "/proc/$SERVER/status"; }

echo "== warm-up $WARMUP"
load "$WARMUP" | grep -E "Requests/sec|Non-2xx|Socket errors"
warm=$(rss_kb)
(while sleep "$SAMPLE_S"; do rss_kb; done >"$WORK/rss.txt") &
SAMPLER=$!
EXTRA_PIDS=$SAMPLER
echo "== soak $DURATION, step batch $BATCH binary, $CONNECTIONS connections"
load "$DURATION" | grep -E "Requests/sec|Non-2xx|Socket errors|requests in|Latency  |^ +(50|75|90|99)%"
kill "$SAMPLER" 2>/dev/null || true
end=$(rss_kb)
peak=$(sort -n "$WORK/rss.txt" | tail -1)
echo "== RSS after warm-up ${warm} kB, at the end ${end} kB, highest sample ${peak:-$end} kB"
awk -v w="$warm" -v e="$end" 'BEGIN { printf "== RSS growth after warm-up: %+.1f%%\n", 100 * (e - w) / w }'
echo "== server log lines at warn or error: $(grep -c -E 'WARN|ERROR' "$WORK/server.log" || true)"
