#!/bin/sh
# Tiles the data in ../shared/data into three geographic pyramids under OUT_DIR: world
# topography (elevation, Terrarium), the Blue Marble (imagery, JPEG) and the SRTM tile N57E011
# (elevation, 90 m). Builds the release binary first. Used by real-earth-demo.sh and
# stream-figures.sh.
# Usage: tools/tile-demo-data.sh OUT_DIR
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
data="$here/../shared/data"
out=$1
mkdir -p "$out"
cd "$here"
cargo build --release --quiet
globus="$here/target/release/globus"
"$globus" tile dem --in "$data/earth-topology-2048x1024.png" --height-scale 25.1 \
    --scheme geographic --force --out "$out/topo" >/dev/null
"$globus" tile imagery --in "$data/bmng-5400x2700.jpg" --scheme geographic --format jpeg \
    --force --out "$out/bmng" >/dev/null
"$globus" tile dem --in "$data/N57E011.hgt" --scheme geographic --force --out "$out/srtm" >/dev/null
