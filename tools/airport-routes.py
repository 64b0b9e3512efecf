#!/usr/bin/env python3
"""Writes a GeoJSON file of great-circle routes between airports of airports.csv, for the
vector benchmark: `tools/airport-routes.py ../shared/data/airports.csv 700 > routes.geojson`.

Routes join random pairs of airports with an IATA code inside Europe (35-70 N, 10 W-40 E),
500 to 1,500 km apart, at a cruise altitude of 10 km (absolute heights), seeded so every
run writes the same file.
"""
import csv
import json
import math
import random
import sys


def main():
    path, count = sys.argv[1], int(sys.argv[2])
    with open(path, newline="", encoding="utf-8") as f:
        airports = [
            (float(r["lon"]), float(r["lat"]), r["iata"])
            for r in csv.DictReader(f)
            if r["iata"] and 35 <= float(r["lat"]) <= 70 and -10 <= float(r["lon"]) <= 40
        ]
    rng = random.Random(17)
    features = []
    while len(features) < count:
        a, b = rng.sample(airports, 2)
        phi1, phi2 = math.radians(a[1]), math.radians(b[1])
        d = 6371.0 * math.acos(
            min(1.0, math.sin(phi1) * math.sin(phi2)
                + math.cos(phi1) * math.cos(phi2) * math.cos(math.radians(b[0] - a[0])))
        )
        if not 500 <= d <= 1500:
            continue
        features.append({
            "type": "Feature",
            "properties": {"name": f"{a[2]}-{b[2]}", "clamp": "absolute",
                           "stroke": "#66ffcc", "stroke-width": 1.5},
            "geometry": {"type": "LineString",
                         "coordinates": [[a[0], a[1], 10000.0], [b[0], b[1], 10000.0]]},
        })
    json.dump({"type": "FeatureCollection", "features": features}, sys.stdout)


if __name__ == "__main__":
    main()
