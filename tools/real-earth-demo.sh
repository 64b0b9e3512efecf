#!/bin/sh
# The real Earth from the data in ../shared/data, streamed over HTTP on 127.0.0.1:
#   1. `globus tile` makes three geographic pyramids: world topography (elevation, Terrarium),
#      the Blue Marble (imagery, JPEG) and the SRTM tile N57E011 (elevation, 90 m);
#   2. a plain HTTP server serves them;
#   3. `globus render` draws the whole Earth, Europe, and the Swedish west coast near
#      Gothenburg, where the SRTM detail lies over the coarse world topography and procedural
#      refinement continues below both.
# Usage: tools/real-earth-demo.sh [OUT_DIR] [PORT]   (images land in OUT_DIR/*.png)
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-"$here/target/real-earth"}
port=${2:-8765}
"$here/tools/tile-demo-data.sh" "$out/tiles"
globus="$here/target/release/globus"
cd "$here"
python3 -m http.server "$port" --bind 127.0.0.1 --directory "$out/tiles" >"$out/server.log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null' EXIT INT TERM
# Wait for the server to answer.
for _ in 1 2 3 4 5 6 7 8 9 10; do
    python3 -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:$port/topo/metadata.json')" 2>/dev/null && break
    sleep 0.3
done

base="http://127.0.0.1:$port"
sources="--terrain $base/topo --terrain $base/srtm --imagery $base/bmng"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
"$globus" render $sources --camera 10,30,15000000,0,-90 --size 1280x720 \
    --out "$out/earth.png" --stats "$out/earth.json"
"$globus" render $sources --camera 12,50,3000000,0,-90 --size 1280x720 \
    --out "$out/europe.png" --stats "$out/europe.json"
"$globus" render $sources --camera 11.95,57.55,2500,20,-20 --size 1280x720 \
    --out "$out/gothenburg.png" --stats "$out/gothenburg.json"
# The same coast without imagery: heights tinted, so the SRTM relief shows.
"$globus" render --terrain "$base/topo" --terrain "$base/srtm" \
    --camera 11.95,57.55,2500,20,-20 --size 1280x720 --out "$out/gothenburg-relief.png"
echo "images in $out: earth.png europe.png gothenburg.png gothenburg-relief.png"
