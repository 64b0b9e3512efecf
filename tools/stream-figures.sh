#!/bin/sh
# Streaming figures (issue 5), on the data in ../shared/data served with 50 ms added latency
# per request by tools/slow_http.py, 8 requests per host at most (the default):
#   1. jump: everything loaded over the Swedish coast, then a jump of 5,360 km to Dakar at
#      1920x1080; time to the first complete frame and to every wanted tile loaded, three runs
#      each with every frame rasterised (lavapipe shares the cores with the loaders) and with
#      only the first frame rasterised (the data side alone);
#   2. alps-dive in real time: the share of loaded tiles never drawn, and tiles loaded again
#      while cached, for the real-data layers and for the procedural planet;
#   3. imagery far deeper than the terrain: the world topography (engine level 5) draped with
#      a shaded relief of N57E011 (tools/hillshade.py, engine level 12); a jump of 5,360 km
#      from Dakar to 2.5 km above the Swedish coast, time to every wanted tile's geometry and
#      to its imagery, three runs with only the first frame rasterised.
# Usage: tools/stream-figures.sh [OUT_DIR] [PORT]
# On a machine that cannot build (a lent GPU machine), set GLOBUS to a built binary and TILES
# to the output of tools/tile-demo-data.sh made elsewhere.
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-"$here/target/stream-figures"}
port=${2:-8766}
mkdir -p "$out"
tiles=${TILES:-"$out/tiles"}
[ -n "${TILES:-}" ] || "$here/tools/tile-demo-data.sh" "$tiles"
globus=${GLOBUS:-"$here/target/release/globus"}
if [ ! -d "$tiles/relief" ]; then
    python3 "$here/tools/hillshade.py" "$here/../shared/data/N57E011.hgt" "$out/relief.png" 2
    "$globus" tile imagery --in "$out/relief.png" --bounds 11,57,12,58 --scheme geographic \
        --format jpeg --force --out "$tiles/relief" >/dev/null
fi
cd "$here"
python3 "$here/tools/slow_http.py" "$tiles" "$port" 50 2>"$out/server.log" &
server=$!
trap 'kill $server 2>/dev/null' EXIT INT TERM
sleep 1
base="http://127.0.0.1:$port"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
jump="--from 11.95,57.55,3000,20,-20 --to -17.4,14.7,3000,90,-20 --size 1920x1080"
: >"$out/jump.jsonl"
for mode in "" "--no-draw"; do
    for run in 1 2 3; do
        "$globus" bench --terrain "$base/topo" --terrain "$base/srtm" --imagery "$base/bmng" \
            $jump $mode >>"$out/jump.jsonl"
    done
done
"$globus" bench --terrain "$base/topo" --terrain "$base/srtm" --imagery "$base/bmng" \
    --path paths/alps-dive.json --size 960x540 --fps 10 --realtime >"$out/alps-real.json"
"$globus" bench --path paths/alps-dive.json --size 960x540 --fps 10 --realtime \
    >"$out/alps-procedural.json"
deep="--from -17.4,14.7,3000,90,-20 --to 11.7,57.4,2500,60,-25 --size 1920x1080 --no-draw"
: >"$out/deep.jsonl"
for run in 1 2 3; do
    "$globus" bench --terrain "$base/topo" --imagery "$base/bmng" --imagery "$base/relief" \
        $deep >>"$out/deep.jsonl"
done
python3 - "$out" <<'EOF'
import json, statistics, sys
out = sys.argv[1]
runs = [json.loads(l) for l in open(f"{out}/jump.jsonl")]
for drawn in (True, False):
    rs = [r for r in runs if r["frames_drawn"] == drawn]
    print(f"jump {rs[0]['jump_km']:.0f} km, every frame rasterised: {drawn}: "
          f"first complete frame median {statistics.median(r['first_frame_ms'] for r in rs):.0f} ms "
          f"(holes {max(r['first_frame_holes'] for r in rs)}), all wanted tiles loaded median "
          f"{statistics.median(r['all_loaded_ms'] for r in rs):.0f} ms over {len(rs)} runs, "
          f"{rs[0]['tiles_loaded']} tiles")
for name in ("alps-real", "alps-procedural"):
    d = json.load(open(f"{out}/{name}.json"))
    print(f"{name}: loaded {d['tiles_loaded']}, never drawn {d['loaded_never_drawn']} "
          f"({100 * d['loaded_never_drawn_fraction']:.1f} %); from fetched data {d['fetched']}, "
          f"never drawn {d['fetched_never_drawn']} ({100 * d['fetched_never_drawn_fraction']:.1f} %); "
          f"loaded again while cached {d['loaded_again_while_cached']}, "
          f"stopped in flight {d['loads_stopped_in_flight']}, "
          f"requests deferred while moving {d['requests_deferred_while_moving']}, "
          f"frames with every wanted tile drawn {100 * d['complete_frames_fraction']:.1f} %")
runs = [json.loads(l) for l in open(f"{out}/deep.jsonl")]
print(f"imagery deeper than terrain, jump {runs[0]['jump_km']:.0f} km: every wanted tile's geometry "
      f"{statistics.median(r['geometry_loaded_ms'] for r in runs):.0f} ms, with its imagery "
      f"{statistics.median(r['all_loaded_ms'] for r in runs):.0f} ms (medians of {len(runs)}), "
      f"{runs[0]['tiles_loaded']} tiles, {runs[0]['imagery_loaded']} imagery loads")
EOF
