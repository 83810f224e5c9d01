#!/usr/bin/env bash
# Screenshot of a recording in Foxglove Studio with the shipped layout (docs/foxglove-layout.json).
#
# Foxglove Studio's web app is built from @foxglove/studio-base (npm, MPL-2.0; 1.48.0 ships the built
# bundle in assets/). index.html + main.js mount its App with an in-memory layout store holding our
# layout, serve.js serves it and the recording on 127.0.0.1 (with HTTP ranges, for Foxglove's
# remote-file reader), shot.js drives Debian's Chromium headless (puppeteer-core) and saves the PNG.
#
#   scripts/foxglove-screenshot/run.sh [RECORDING.mcap] [OUT.png]
# defaults: out/paper-fig9.mcap (run `cargo run --release -- sim` first), docs/foxglove-paper-fig9.png
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
mcap=$(realpath "${1:-$root/out/paper-fig9.mcap}")
out=$(realpath -m "${2:-$root/docs/foxglove-paper-fig9.png}")
work=${FOXGLOVE_WORK:-/tmp/forcecell-foxglove}
port=${FOXGLOVE_PORT:-8123}

command -v chromium >/dev/null || { apt-get update && apt-get install -y chromium; }
mkdir -p "$work/www"
if [ ! -f "$work/node_modules/@foxglove/studio-base/assets/index.js" ]; then
    (cd "$work" && npm init -y >/dev/null && npm install --no-audit --no-fund \
        @foxglove/studio-base@1.48.0 react@18 react-dom@18 puppeteer-core@24)
fi
cd "$work/www"
ln -sfn "$work/node_modules/@foxglove/studio-base/assets" assets
cp "$work/node_modules/react/umd/react.production.min.js" "$work/node_modules/react-dom/umd/react-dom.production.min.js" .
cp "$here/index.html" "$here/main.js" .
cp "$root/docs/foxglove-layout.json" layout.json
cp "$mcap" recording.mcap
node "$here/serve.js" "$work/www" "$port" &
server=$!
trap 'kill $server' EXIT
sleep 1
NODE_PATH="$work/node_modules" node "$here/shot.js" \
    "http://127.0.0.1:$port/?ds=remote-file&ds.url=http://127.0.0.1:$port/recording.mcap" "$out" 40000
echo "wrote $out"
