#!/usr/bin/env python3
"""Regenerates the independent reference tables used by the Rust tests.

    pip install pyproj mercantile
    python3 tools/make_reference_tables.py

* crates/geo/tests/data/proj_wgs84.json: geodetic (EPSG:4979) to geocentric (EPSG:4978)
  conversions computed by PROJ through pyproj, at the poles, along the antimeridian, high
  above the planet and below the ellipsoid.
* crates/tiling/tests/data/mercantile.json: Web Mercator tiles, quadkeys and bounds computed
  by the mercantile package.

The tables are committed so the test suite needs neither package; rerun this script only to
extend them.
"""
import json
import os
import random

import mercantile
import pyproj

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def proj_table():
    tr = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    rng = random.Random(4978)
    pts = []
    for lat in (90.0, -90.0, 89.9999999, -89.9999999, 0.0, 45.0, -45.0):
        for lon in (-180.0, 180.0, 179.9999999, -179.9999999, 0.0, 7.6):
            for h in (-500.0, 0.0, 1.0, 8848.0, 400_000.0, 35_786_000.0, 40_000_000.0):
                pts.append((lon, lat, h))
    for _ in range(300):
        pts.append((rng.uniform(-180, 180), rng.uniform(-90, 90), rng.uniform(-500, 4.0e7)))
    rows = []
    for lon, lat, h in pts:
        x, y, z = tr.transform(lon, lat, h)
        rows.append({"lon": lon, "lat": lat, "h": h, "x": x, "y": y, "z": z})
    return {
        "source": f"pyproj {pyproj.__version__} / PROJ {pyproj.proj_version_str}, EPSG:4979 -> EPSG:4978",
        "rows": rows,
    }


def mercantile_table():
    rng = random.Random(3857)
    rows = []
    cases = [(7.6, 46.0, z) for z in range(0, 23)]
    cases += [(-179.9999, 85.0, 3), (179.9999, -85.0, 5), (0.0, 0.0, 1), (-122.4194, 37.7749, 12)]
    for _ in range(200):
        cases.append((rng.uniform(-180, 180), rng.uniform(-85.05, 85.05), rng.randint(0, 24)))
    for lon, lat, z in cases:
        t = mercantile.tile(lon, lat, z)
        b = mercantile.bounds(t)
        rows.append({
            "lon": lon, "lat": lat, "z": z, "x": t.x, "y": t.y,
            "quadkey": mercantile.quadkey(t),
            "west": b.west, "south": b.south, "east": b.east, "north": b.north,
        })
    return {"source": f"mercantile {mercantile.__version__}", "rows": rows}


def write(path, obj):
    path = os.path.join(ROOT, path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(obj, f, indent=0)
        f.write("\n")


if __name__ == "__main__":
    write("crates/geo/tests/data/proj_wgs84.json", proj_table())
    write("crates/tiling/tests/data/mercantile.json", mercantile_table())
