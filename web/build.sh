#!/usr/bin/env bash
# Builds the browser viewer (web/, wasm32) into target/viewer/ (or the folder given), which
# `portico serve` then serves at `/`. Two ways to a wasm32 toolchain, tried in this order:
#   rustup (macOS, most Linux): `rustup target add wasm32-unknown-unknown`;
#   Debian/Ubuntu without rustup's target: `apt-get install rustc-web cargo-web rust-web-src
#   lld-16` (std is built for wasm32 from its sources).
# Either way wasm-bindgen-cli of the same version as the wasm-bindgen crate in Cargo.lock:
#   cargo install wasm-bindgen-cli --version <that version>
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/viewer}
bindgen_version=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
if [ "$(wasm-bindgen --version 2>/dev/null | awk '{print $2}')" != "$bindgen_version" ]; then
  echo "web/build.sh: needs wasm-bindgen $bindgen_version: cargo install wasm-bindgen-cli --version $bindgen_version" >&2
  exit 1
fi
if command -v rustup >/dev/null && rustup target list --installed 2>/dev/null | grep -qx wasm32-unknown-unknown; then
  echo "web/build.sh: rustup's wasm32-unknown-unknown target ($(rustc --version))"
  CARGO_TARGET_DIR=target/wasm cargo build --locked --profile wasm -p portico-web \
    --target wasm32-unknown-unknown
else
  missing=()
  for tool in /usr/bin/rustc /usr/bin/cargo /usr/lib/rustlib/src/rust/library wasm-ld-16; do
    [ -e "$tool" ] || command -v "$tool" >/dev/null || missing+=("$tool")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    {
      echo "web/build.sh: no wasm32 toolchain."
      echo "  With rustup: rustup target add wasm32-unknown-unknown"
      echo "  On Debian/Ubuntu: apt-get install rustc-web cargo-web rust-web-src lld-16 (missing: ${missing[*]})"
    } >&2
    exit 1
  fi
  echo "web/build.sh: Debian's rustc-web, std built for wasm32 from rust-web-src ($(/usr/bin/rustc --version))"
  RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_LINKER=wasm-ld-16 \
    CARGO_TARGET_DIR=target/wasm /usr/bin/cargo build --locked --profile wasm -p portico-web \
    --target wasm32-unknown-unknown -Zbuild-std=std,panic_abort
fi
mkdir -p "$out"
wasm-bindgen --target web --no-typescript --remove-name-section --remove-producers-section \
  --out-dir "$out" target/wasm/wasm32-unknown-unknown/wasm/portico_web.wasm
cp web/static/index.html "$out/"
# Compressed beside the originals: the server sends these to browsers that accept gzip.
gzip -9kf "$out/portico_web_bg.wasm" "$out/portico_web.js" "$out/index.html"
wasm=$(stat -c %s "$out/portico_web_bg.wasm" 2>/dev/null || stat -f %z "$out/portico_web_bg.wasm")
gz=$(stat -c %s "$out/portico_web_bg.wasm.gz" 2>/dev/null || stat -f %z "$out/portico_web_bg.wasm.gz")
echo "viewer in $out: wasm $((wasm / 1024)) KiB ($((gz / 1024)) KiB gzipped)"
# The bundle's budget, gzipped: a ratchet (the target is 600 KB; the WebGL2 path's shader
# translator and wgpu-core are half of today's code). Past it the build fails, so the bundle
# cannot grow unnoticed.
budget_kib=${PORTICO_BUNDLE_BUDGET_KIB:-1150}
if [ $((gz / 1024)) -gt "$budget_kib" ]; then
  echo "web/build.sh: the wasm is $((gz / 1024)) KiB gzipped, over its budget of $budget_kib KiB" >&2
  exit 1
fi
