#!/usr/bin/env bash
# Build the browser demo into a static folder (default examples/web/dist):
# index.html, main.js, and the WebAssembly module with its JavaScript glue.
# Serve it with any static server, e.g.
#   python3 -m http.server -d examples/web/dist 8000
# Installs the wasm32 target and the wasm-bindgen CLI matching the crate when
# they are missing.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
out=$(realpath -m "${1:-$here/dist}")
cd "$root"

if command -v rustup >/dev/null 2>&1 && ! rustup target list --installed | grep -qx wasm32-unknown-unknown; then
    rustup target add wasm32-unknown-unknown
fi
# The CLI must match the wasm-bindgen crate in Cargo.lock exactly.
version=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
if [ "$(wasm-bindgen --version 2>/dev/null | awk '{ print $2 }')" != "$version" ]; then
    echo "installing wasm-bindgen-cli $version" >&2
    cargo install --quiet wasm-bindgen-cli --version "$version"
fi

cargo build --release --target wasm32-unknown-unknown -p yarnify-web
rm -rf "$out"
mkdir -p "$out"
# Cargo puts the module under CARGO_TARGET_DIR when that is set.
target=${CARGO_TARGET_DIR:-$root/target}
wasm-bindgen --target web --no-typescript --out-dir "$out/pkg" "$target/wasm32-unknown-unknown/release/yarnify_web.wasm"
cp "$here"/www/* "$out/"
echo "built $out ($(du -sh "$out" | cut -f1)); serve it, e.g.: python3 -m http.server -d $out 8000"
