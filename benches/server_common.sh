# Sourced by the server load scripts: request bodies in $WORK, a release
# nuno-server serving models/ on 127.0.0.1:$PORT (log in $WORK/server.log,
# pid in $SERVER) once it is ready, both removed on exit, and `post_load`:
# wrk with `benches/wrk_post.lua` (duration, url, body file, content type[, accept]).
set -euo pipefail
cd "$(dirname "$0")/.."
CONNECTIONS="${CONNECTIONS:-4}"
WORK="$(mktemp -d)"
SERVER=""
EXTRA_PIDS=""
trap 'kill $SERVER $EXTRA_PIDS 2>/dev/null || true; rm -rf "$WORK"' EXIT

.venv/bin/python benches/server_bodies.py "$WORK"
"${CARGO_TARGET_DIR:-target}/release/nuno-server" --models models --addr "127.0.0.1:$PORT" 2>"$WORK/server.log" &
SERVER=$!
until curl -fs "http://127.0.0.1:$PORT/readyz" >/dev/null; do sleep 0.2; done

post_load() {
  wrk -t2 -c"$CONNECTIONS" -d"$1" --timeout 120s --latency -s benches/wrk_post.lua "$2" -- "$3" "$4" ${5:-}
}
