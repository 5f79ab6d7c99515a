#!/usr/bin/env bash
# Segment serving: `portico serve` against nginx serving the same bytes as static files, on
# loopback, in one run (DESIGN §8: Portico ≥ 0.8× nginx's throughput).
#
#   bench/segments.sh DB.portico [SECONDS] [CONNECTIONS]
#
# Needs wrk, nginx and curl (apt-get install wrk nginx-light curl) and a release build
# (cargo build --release). Every segment of DB is fetched from Portico once and written to a
# directory nginx serves; then wrk requests all segments in turn from each server, with the
# same threads, connections and duration. Both servers get two workers (this machine's cores).
set -euo pipefail
db=$(realpath "$1")
secs=${2:-10}
conns=${3:-32}
here=$(cd "$(dirname "$0")" && pwd)
portico="$here/../target/release/portico"
work=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; [ -f "$work/nginx.pid" ] && kill "$(cat "$work/nginx.pid")" 2>/dev/null; rm -rf "$work"' EXIT

port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
pp=$(port); np=$(port)
"$portico" serve "$db" --listen "127.0.0.1:$pp" --threads 2 2>"$work/portico.log" &
for _ in $(seq 100); do curl -fs "http://127.0.0.1:$pp/healthz" >/dev/null && break; sleep 0.05; done
count=$(curl -fs -H 'accept: application/json' "http://127.0.0.1:$pp/v1/manifest" \
  | python3 -c 'import json,sys; print(len(json.load(sys.stdin)["segments"]))')
mkdir -p "$work/www/seg"
for ((i = 0; i < count; i++)); do
  curl -fs "http://127.0.0.1:$pp/v1/segments/$i" -o "$work/www/seg/$i"
done
chmod -R a+rX "$work"  # nginx workers run as an unprivileged user
bytes=$(du -sb "$work/www/seg" | cut -f1)
cat >"$work/nginx.conf" <<CONF
worker_processes 2;
pid $work/nginx.pid;
error_log $work/error.log warn;
events { worker_connections 1024; }
http {
  access_log off;
  sendfile on;
  tcp_nopush on;
  keepalive_requests 100000;
  default_type application/octet-stream;
  client_body_temp_path $work/tmp; proxy_temp_path $work/tmp;
  fastcgi_temp_path $work/tmp; uwsgi_temp_path $work/tmp; scgi_temp_path $work/tmp;
  server { listen 127.0.0.1:$np; root $work/www; etag on; }
}
CONF
nginx -c "$work/nginx.conf" -p "$work"
for _ in $(seq 100); do curl -fs "http://127.0.0.1:$np/seg/0" >/dev/null && break; sleep 0.05; done

echo "segments: $count, $((bytes / 1024)) KiB in all; wrk -t2 -c$conns -d${secs}s, each segment in turn"
run() { # URL PREFIX NAME
  wrk -t2 -c"$conns" -d"${secs}s" --latency -s "$here/segments.lua" "$1" -- "$2" "$count" >"$work/$3.txt"
  awk -v name="$3" '/Requests\/sec/ {rps=$2} /Transfer\/sec/ {tr=$2} /^ +99%/ {p99=$2} /Non-2xx/ {bad=$NF}
    END {printf "%-8s %10.0f req/s %10s/s  latency p99 %-8s non-2xx %d\n", name, rps, tr, p99, bad}' "$work/$3.txt"
}
rps() { awk '/Requests\/sec/ {print $2}' "$work/$1.txt"; }
run "http://127.0.0.1:$np" /seg/ nginx
run "http://127.0.0.1:$pp" /v1/segments/ portico
run "http://127.0.0.1:$np" /seg/ nginx2
run "http://127.0.0.1:$pp" /v1/segments/ portico2
python3 - "$(rps nginx)" "$(rps portico)" "$(rps nginx2)" "$(rps portico2)" <<'PY'
import sys
n1, p1, n2, p2 = map(float, sys.argv[1:])
print(f"portico / nginx: {(p1 + p2) / (n1 + n2):.2f} (two alternating rounds: {p1 / n1:.2f}, {p2 / n2:.2f})")
PY
