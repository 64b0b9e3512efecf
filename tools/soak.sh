#!/bin/sh
# Soak figure (issue 5): fly between random views for SECONDS in real time at 1920x1080 against
# the demo data served by tools/slow_http.py with 50 ms added to every request and a fault
# injected into 10 % of tile requests, under one memory budget of BUDGET_MIB; prints a summary
# (resident memory medians and peaks per period, loads, failures) and plots resident memory
# against the budget (tools/plot_soak.py, look at the PNG).
# Usage: tools/soak.sh [OUT_DIR] [SECONDS] [BUDGET_MIB] [PORT]
# GLOBUS and TILES as for tools/stream-figures.sh.
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-"$here/target/soak"}
seconds=${2:-1800}
budget=${3:-512}
port=${4:-8790}
mkdir -p "$out"
tiles=${TILES:-"$out/tiles"}
[ -n "${TILES:-}" ] || "$here/tools/tile-demo-data.sh" "$tiles"
globus=${GLOBUS:-"$here/target/release/globus"}
cd "$here"
python3 "$here/tools/slow_http.py" "$tiles" "$port" 50 0.1 2>"$out/server.log" &
server=$!
trap 'kill $server 2>/dev/null' EXIT INT TERM
sleep 1
base="http://127.0.0.1:$port"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
"$globus" bench --soak "$seconds" --memory-mb "$budget" --size 1920x1080 \
    --terrain "$base/topo" --terrain "$base/srtm" --imagery "$base/bmng" \
    >"$out/soak.jsonl" 2>"$out/soak.err"
python3 "$here/tools/plot_soak.py" "$out/soak.jsonl" "$out/soak.png"
python3 - "$out/soak.jsonl" <<'EOF'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
summary = [r for r in rows if r.get("summary")]
rows = [r for r in rows if not r.get("summary")]
last = rows[-1]
print(f"budget {last['memory_budget_mib']:.0f} MiB: baseline {last['baseline_mib']:.0f} MiB, "
      f"tile cache share {last['cache_budget_mib']:.0f} MiB, GPU pools {last['gpu_capacity']} slots "
      f"({last['gpu_pool_mib']:.0f} MiB)")
end = last["t_s"] / 60
edges = [3, 10, 20, 30, 60, 120]
periods = [(a, b) for a, b in zip([0] + edges, edges) if a < end and a >= 3]
for a, b in periods:
    rss = [r["rss_mib"] for r in rows if a * 60 <= r["t_s"] < b * 60]
    if rss:
        print(f"minutes {a}-{min(b, end):.0f}: RSS median {statistics.median(rss):.0f} MiB, "
              f"peak {max(rss):.0f} MiB, samples over the budget "
              f"{sum(x > last['memory_budget_mib'] for x in rss)} of {len(rss)}")
last = summary[-1] if summary else last
print(f"{end:.1f} minutes: {last['loaded']} tiles loaded, {last['failed']} failures, "
      f"{last['retries']} retries, {last['frames']} frames"
      + (f", peak RSS {last['max_rss_mib']:.0f} MiB" if "max_rss_mib" in last else ""))
EOF
