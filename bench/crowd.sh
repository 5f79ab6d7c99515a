#!/usr/bin/env bash
# A crowd of 1,000 on the default policy (issue #41's figures, docs/performance.md): on one
# server, the stream stress at 1, 256 and 1,000 sessions and then the `/v1/prefetch` stress at
# 1,000 clients; then each stress alone on a fresh server (a cold crowd, arriving at once).
#
#   bench/crowd.sh DB.portico PATH.json [OUT_DIR]
#
# PATH.json from `portico path --db DB.portico --kind tour --legs 6 -o PATH.json`. Uses port
# 7811; PORTICO names the binary (default: this checkout's release build). About 3 minutes.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin=${PORTICO:-$root/target/release/portico}
[ -x "$bin" ] || { echo "error: no $bin: run cargo build --release first" >&2; exit 1; }
[ $# -ge 2 ] || { echo "usage: bench/crowd.sh DB.portico PATH.json [OUT_DIR]" >&2; exit 2; }
db=$1 path=$2 out=${3:-crowd-figures}
url=http://127.0.0.1:7811
mkdir -p "$out"
server=
up() {
  "$bin" serve "$db" --listen 127.0.0.1:7811 > "$out/server.log" 2>&1 &
  server=$!
  for _ in $(seq 1 60); do curl -sf $url/healthz > /dev/null && return; sleep 1; done
  echo "error: the server did not start (see $out/server.log)" >&2
  exit 1
}
down() { kill "$server"; wait "$server" 2> /dev/null || true; }
trap 'kill $server 2> /dev/null || true' EXIT
stream() { "$bin" loadtest --server $url --path "$path" --stress "$1" --stream --stress-seconds 8 --link rtt=0ms,rate=1kbit -o "$out/$2"; }
pull() { "$bin" loadtest --server $url --path "$path" --stress 1000 -o "$out/$1"; }

echo "== one server: stream 1, 256, 1,000 sessions, then /v1/prefetch at 1,000 clients"
up; stream 1,256,1000 stream; pull pull; down
echo "== a cold crowd: the stream at 1,000 sessions alone on a fresh server"
up; stream 1000 stream-cold; down
echo "== a cold crowd: /v1/prefetch at 1,000 clients alone on a fresh server, then again"
up; pull pull-cold; pull pull-again; down
