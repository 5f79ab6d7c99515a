#!/usr/bin/env bash
# The Performance figures for `soda` (docs/performance.md), by the commands written in its table, in order.
#
#   bench/readme.sh [DIR] [--sweep] [--mega]
#
# DIR (default readme-figures/) receives the models and every command's output; each step
# prints its command and wall time. The policy sweep (about 5 minutes) and `mega` (about
# 10 minutes) run only when asked. Needs a release build (`cargo build --release`) and curl;
# uses port 7878 as the documents do. About 15 minutes on 2 cores without the options.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin=${PORTICO:-$root/target/release/portico}
[ -x "$bin" ] || { echo "error: no $bin: run cargo build --release first" >&2; exit 1; }

dir=readme-figures sweep= mega=
for a in "$@"; do
  case $a in
    --sweep) sweep=1 ;;
    --mega) mega=1 ;;
    -*) echo "error: unknown option $a" >&2; exit 2 ;;
    *) dir=$a ;;
  esac
done
mkdir -p "$dir" && cd "$dir"

server=
stop() {
  if [ -n "$server" ]; then
    kill "$server" 2>/dev/null || true
    wait "$server" 2>/dev/null || true # it drains, then exits on SIGTERM
  fi
  server=
}
trap stop EXIT
# `portico serve F` in the background, on the documents' port; returns once /healthz answers.
# (Started directly, not through a function or subshell: $! must be the server's pid.)
serve() {
  stop
  "$bin" serve "$@" >"serve-$(basename "$1").log" 2>&1 &
  server=$!
  for _ in $(seq 100); do
    curl -fs http://127.0.0.1:7878/healthz >/dev/null 2>&1 && return
    sleep 0.1
  done
  echo "error: portico serve $1 did not answer on 127.0.0.1:7878" >&2
  exit 1
}
# Prints the command, runs it, prints its wall time and peak RSS.
step() {
  echo
  echo "== portico $*"
  /usr/bin/time -f "== %e s, %M KB peak RSS" "$bin" "$@"
}

step generate --preset soda -o soda.glb
step build soda.glb -o soda.portico
step build soda.glb -o soda.nohier.portico --no-hierarchy
step build soda.glb -o soda.flat.portico --flatten
step build soda.glb -o soda.flat.z.portico --flatten --compress
ls -l soda.glb soda.portico soda.nohier.portico soda.flat.portico soda.flat.z.portico
step inspect soda.portico
step inspect soda.flat.portico
step inspect soda.flat.z.portico
step path --db soda.portico --kind tour --legs 6 -o tour.json
step verify soda.portico --rays 50000
step cull soda.portico --tour 20

serve soda.portico
step loadtest --path tour.json --stress 1,16,64 --policy depth=16,gran=object,range=direction,look=any -o st
step loadtest --path tour.json --stress 1,16,64 --policy depth=16,gran=object,range=direction,look=any -o st-closed --closed-loop
# A crowd on the push stream: shared need lists, then every observer its own (the baseline).
step loadtest --path tour.json --stress 1,64,256,1000 --stream --stress-seconds 8 --link rtt=0ms,rate=1kbit --policy depth=16,gran=object,range=direction,look=any -o ss
step loadtest --path tour.json --stress 1,64,256,1000 --stream --stress-seconds 8 --link rtt=0ms,rate=1mbit --policy depth=16,gran=object,range=direction,look=any -o ss-push
serve soda.portico --exact-answers
step loadtest --path tour.json --stress 1,64,256,1000 --stream --stress-seconds 8 --link rtt=0ms,rate=1kbit --policy depth=16,gran=object,range=direction,look=any -o ss-exact --baseline ss

serve soda.flat.portico
step walk --server http://127.0.0.1:7878 --path tour.json --cache-mb 64 --max-frames 2400 -o w64
step walk --server http://127.0.0.1:7878 --path tour.json --cache-mb 8 --max-frames 2400 -o w8
step walk --server http://127.0.0.1:7878 --elision optimize --max-frames 600 -o w-optimize
step walk --server http://127.0.0.1:7878 --elision impostors --max-frames 600 -o w-impostors
step loadtest --clients 8 --path tour.json --max-frames 400 --policy depth=16,gran=object,range=frustum,look=any -o lt
step loadtest --clients 8 --path tour.json --max-frames 400 --policy depth=16,gran=object,range=frustum,look=any,imp=1 -o lt-imp
if [ -n "$sweep" ]; then
  step loadtest --clients 8 --path tour.json --sweep --link rtt=20ms,rate=100mbit -o lt_sweep
fi
step loadtest --clients 8 --path tour.json --max-frames 400 --link rtt=50ms,rate=10mbit --policy depth=16,gran=object,range=frustum,look=any -o lt-slow
step loadtest --clients 8 --path tour.json --max-frames 400 --link rtt=20ms,rate=100mbit --policy depth=16,gran=object,range=frustum,look=any -o lt-fast
stop

serve soda.flat.z.portico
step loadtest --clients 8 --path tour.json --max-frames 400 --link rtt=50ms,rate=10mbit --policy depth=16,gran=object,range=frustum,look=any -o lt-slow-z
step loadtest --clients 8 --path tour.json --max-frames 400 --link rtt=20ms,rate=100mbit --policy depth=16,gran=object,range=frustum,look=any -o lt-fast-z
stop

step bench --db soda.portico --path tour.json --size 640x480 --max-frames 400 --budget-ms 50 -o b
step bench --db soda.portico --path tour.json --size 640x480 --max-frames 400 --budget-ms 4 -o b4
for ms in 50 6 4; do
  step bench --db soda.portico --path tour.json --max-frames 400 \
    --algorithms regular,optimize,impostors --budget-ms "$ms" -o "bi$ms"
done

if [ -n "$mega" ]; then
  step generate --preset mega -o mega.glb
  step build mega.glb -o mega.portico
  step build mega.glb -o mega.nohier.portico --no-hierarchy
  ls -l mega.glb mega.portico mega.nohier.portico
  step path --db mega.portico --kind tour --legs 6 -o mtour.json
  for ms in 50 6; do
    step bench --db mega.portico --path mtour.json --max-frames 400 \
      --algorithms regular,optimize,impostors --budget-ms "$ms" -o "mbi$ms"
  done
  # Issue #17's comparison: prefetch, demand fetch and the oracle on flattened mega.
  step build mega.glb -o mega.flat.portico --flatten --no-hierarchy
  step build mega.glb -o mega.flat.z.portico --flatten --compress --no-hierarchy
  step inspect mega.flat.z.portico
  serve mega.flat.portico
  for link in rtt=50ms,rate=10mbit rtt=20ms,rate=100mbit; do
    step loadtest --clients 8 --path mtour.json --max-frames 400 --link "$link" -o "mlt-${link%%,*}"
  done
  step loadtest --clients 4 --path mtour.json --max-frames 400 --link rtt=20ms,rate=100mbit \
    --cache-mb 4,16,64,256 -o mcs
  stop
fi
echo
echo "== done: every command above is docs/performance.md's; outputs in $PWD"
