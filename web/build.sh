#!/usr/bin/env bash
# Builds the browser viewer (web/, wasm32) into target/viewer/ (or the folder given), which
# `portico serve` then serves at `/`. Needs Debian's rustc-web, cargo-web, rust-web-src and
# lld-16 (std is built for wasm32 from the sources: rustup cannot add the target on these
# machines) and wasm-bindgen-cli of the same version as the wasm-bindgen crate in Cargo.lock.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/viewer}
bindgen_version=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
for tool in /usr/bin/rustc /usr/bin/cargo wasm-ld-16; do
  command -v "$tool" >/dev/null || {
    echo "web/build.sh: $tool is missing: apt-get install rustc-web cargo-web rust-web-src lld-16" >&2
    exit 1
  }
done
if [ "$(wasm-bindgen --version 2>/dev/null | awk '{print $2}')" != "$bindgen_version" ]; then
  echo "web/build.sh: needs wasm-bindgen $bindgen_version: cargo install wasm-bindgen-cli --version $bindgen_version" >&2
  exit 1
fi
RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_LINKER=wasm-ld-16 \
  CARGO_TARGET_DIR=target/wasm /usr/bin/cargo build --locked --release -p portico-web \
  --target wasm32-unknown-unknown -Zbuild-std=std,panic_abort
mkdir -p "$out"
wasm-bindgen --target web --no-typescript --out-dir "$out" \
  target/wasm/wasm32-unknown-unknown/release/portico_web.wasm
cp web/static/index.html "$out/"
# Compressed beside the originals: the server sends these to browsers that accept gzip.
gzip -9kf "$out/portico_web_bg.wasm" "$out/portico_web.js" "$out/index.html"
wasm=$(stat -c %s "$out/portico_web_bg.wasm")
gz=$(stat -c %s "$out/portico_web_bg.wasm.gz")
echo "viewer in $out: wasm $((wasm / 1024)) KiB ($((gz / 1024)) KiB gzipped)"
