#!/usr/bin/env python3
"""Regenerates the independent reference tables used by the Rust tests.

    pip install pyproj mercantile
    python3 tools/make_reference_tables.py

* crates/geo/tests/data/proj_wgs84.json: geodetic (EPSG:4979) to geocentric (EPSG:4978)
  conversions computed by PROJ through pyproj, at the poles, along the antimeridian, high
  above the planet and below the ellipsoid.
* crates/tiling/tests/data/mercantile.json: Web Mercator tiles, quadkeys and bounds computed
  by the mercantile package.
* crates/geo/tests/data/pvlib_sun.json: the Sun's zenith angle (without refraction) and
  azimuth seen from places between 78 S and 70 N at moments between 1990 and 2060, by NREL's
  SPA as pvlib implements it (`pip install pvlib`; run with `sun` to write this table alone).

The tables are committed so the test suite needs neither package; rerun this script only to
extend them.
"""
import json
import os
import random

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def proj_table():
    import pyproj

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
    import mercantile

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


def sun_table():
    import pandas as pd
    import pvlib

    rng = random.Random(1985)
    places = [
        ("Zurich", 47.37, 8.54, 408.0),
        ("Sydney", -33.87, 151.21, 39.0),
        ("Tromso", 69.65, 18.96, 10.0),
        ("McMurdo", -77.85, 166.67, 10.0),
        ("Quito", -0.18, -78.47, 2850.0),
        ("Honolulu", 21.31, -157.86, 5.0),
        ("Reykjavik", 64.15, -21.94, 20.0),
        ("Anchorage", 61.22, -149.90, 30.0),
        ("Singapore", 1.35, 103.82, 15.0),
        ("Ushuaia", -54.80, -68.30, 20.0),
    ]
    start = pd.Timestamp("1990-01-01T00:00:00Z").value // 10**9
    end = pd.Timestamp("2060-12-31T00:00:00Z").value // 10**9
    rows = []
    for name, lat, lon, h in places:
        times = sorted(rng.randrange(start, end) for _ in range(30))
        index = pd.DatetimeIndex(pd.to_datetime(times, unit="s", utc=True))
        sp = pvlib.solarposition.get_solarposition(index, lat, lon, altitude=h, method="nrel_numpy")
        for t, (_, r) in zip(times, sp.iterrows()):
            rows.append({
                "place": name, "unix_s": t, "lat": lat, "lon": lon, "height_m": h,
                "zenith": round(float(r["zenith"]), 7), "azimuth": round(float(r["azimuth"]), 7),
            })
    return {"source": f"pvlib {pvlib.__version__} nrel_numpy (SPA), zenith without refraction", "rows": rows}


def write(path, obj):
    path = os.path.join(ROOT, path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(obj, f, indent=0)
        f.write("\n")


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["sun"]:
        write("crates/geo/tests/data/pvlib_sun.json", sun_table())
        sys.exit(0)
    write("crates/geo/tests/data/pvlib_sun.json", sun_table())
    write("crates/geo/tests/data/proj_wgs84.json", proj_table())
    write("crates/tiling/tests/data/mercantile.json", mercantile_table())
