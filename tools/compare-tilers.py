#!/usr/bin/env python3
"""Times `globus tile` against the tilers people use today, side by side in one run.

    python3 tools/compare-tilers.py [--runs 5] [--threads 2]

Imagery: ../shared/data/bmng-5400x2700.jpg to geographic levels 0-5, 256 px PNG tiles,
against gdal2tiles.py (Debian gdal-bin; geodetic profile with --tmscompatible, which has the
same two 180-degree roots at level 0). Debian's gdal2tiles (GDAL 3.6) cannot write JPEG, so
both write PNG.

Elevation: ../shared/data/N57E011.hgt to Web Mercator levels 0-11, Mapbox Terrain-RGB PNG,
512 px tiles (rio-rgbify's tile size), MBTiles, against `rio rgbify` (PyPI rio-rgbify).

Each tool runs --runs times with the same number of worker processes/threads, writing to a
fresh path each time (all outputs are deleted only at the end, so no run pays for another's
deletions); the script prints the median wall time, tiles/s and the ratio as JSON.
Requires: apt-get install gdal-bin; pip install rio-rgbify; cargo build --release.
"""

import argparse
import json
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "..", "shared", "data")
GLOBUS = os.path.join(ROOT, "target", "release", "globus")


def timed(cmd, **kw):
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, **kw)
    return time.perf_counter() - t


def count_files(path, ext):
    return sum(1 for _, _, fs in os.walk(path) for f in fs if f.endswith(ext))


def count_mbtiles(path):
    with sqlite3.connect(path) as db:
        return db.execute("SELECT count(*) FROM tiles").fetchone()[0]


def summarise(name, times, tiles):
    med = statistics.median(times)
    return {
        "tool": name,
        "runs": len(times),
        "tiles": tiles,
        "median_s": round(med, 3),
        "min_s": round(min(times), 3),
        "max_s": round(max(times), 3),
        "tiles_per_s": round(tiles / med, 1),
    }


def imagery(work, runs, threads):
    src = os.path.join(DATA, "bmng-5400x2700.jpg")
    vrt = os.path.join(work, "bmng.vrt")
    subprocess.run(
        ["gdal_translate", "-q", "-of", "VRT", "-a_ullr", "-180", "90", "180", "-90",
         "-a_srs", "EPSG:4326", src, vrt],
        check=True,
    )
    g, o = [], []
    tiles_g = tiles_o = 0
    for i in range(runs):
        out = os.path.join(work, f"gdal2tiles-{i}")
        g.append(timed(["gdal2tiles.py", "-q", "-p", "geodetic", "--tmscompatible", "-z", "0-5",
                        f"--processes={threads}", vrt, out]))
        tiles_g = count_files(out, ".png")
        out = os.path.join(work, f"globus-img-{i}")
        o.append(timed([GLOBUS, "tile", "imagery", "--in", src, "--out", out, "--scheme",
                        "geographic", "--format", "png", "--min-level", "0", "--max-level", "5",
                        "--tile-size", "256", "--threads", str(threads)]))
        tiles_o = count_files(out, ".png")
    a, b = summarise("gdal2tiles.py", g, tiles_g), summarise("globus tile imagery", o, tiles_o)
    return {"case": "imagery bmng-5400x2700.jpg, geographic z0-5, 256 px PNG", "peer": a,
            "globus": b, "ratio_tiles_per_s": round(b["tiles_per_s"] / a["tiles_per_s"], 2)}


def elevation(work, runs, threads):
    src = os.path.join(DATA, "N57E011.hgt")
    r, o = [], []
    tiles_r = tiles_o = 0
    for i in range(runs):
        out = os.path.join(work, f"rio-{i}.mbtiles")
        r.append(timed(["rio", "rgbify", "-b", "-10000", "-i", "0.1", "--min-z", "0", "--max-z",
                        "11", "-j", str(threads), "--format", "png", src, out]))
        tiles_r = count_mbtiles(out)
        out = os.path.join(work, f"globus-dem-{i}.mbtiles")
        o.append(timed([GLOBUS, "tile", "dem", "--in", src, "--out", out, "--scheme",
                        "webmercator", "--encoding", "mapbox", "--tile-size", "512",
                        "--min-level", "0", "--max-level", "11", "--threads", str(threads)]))
        tiles_o = count_mbtiles(out)
    a, b = summarise("rio rgbify", r, tiles_r), summarise("globus tile dem", o, tiles_o)
    return {"case": "elevation N57E011.hgt, webmercator z0-11, 512 px Terrain-RGB PNG, MBTiles",
            "peer": a, "globus": b,
            "ratio_tiles_per_s": round(b["tiles_per_s"] / a["tiles_per_s"], 2)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--only", choices=["imagery", "elevation"])
    args = ap.parse_args()
    for tool in ["gdal2tiles.py", "gdal_translate", "rio"]:
        if shutil.which(tool) is None:
            sys.exit(f"compare-tilers: {tool} not found (apt-get install gdal-bin; pip install rio-rgbify)")
    if not os.path.exists(GLOBUS):
        subprocess.run(["cargo", "build", "--release", "-p", "globus"], cwd=ROOT, check=True)
    work = tempfile.mkdtemp(prefix="globus-compare-", dir=os.path.join(ROOT, "target"))
    try:
        results = []
        if args.only in (None, "imagery"):
            results.append(imagery(work, args.runs, args.threads))
        if args.only in (None, "elevation"):
            results.append(elevation(work, args.runs, args.threads))
        print(json.dumps({"threads": args.threads, "results": results}, indent=2))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
