#!/usr/bin/env python3
"""Independent check of Globus's densified geodesics and rhumb lines (reads JSON on stdin).

For each path {"kind", "a", "b", "h", "mids"}: every midpoint Globus draws (lon, lat, height
of the drawn straight piece's middle) is compared with the true path, and the largest
deviation in metres is printed per path as a JSON list.

* geodesic: geographiclib's geodesic from a with the azimuth towards b, at the distance of
  the midpoint from a; deviation = ECEF distance (WGS84, own formula) between the two,
  heights included.
* rhumb: the rhumb line from a towards b at the midpoint's latitude (isometric latitude,
  own formula); deviation = the distance along the parallel times the cosine of the bearing
  (its part across the line), and the height difference.
"""
import json
import math
import sys

from geographiclib.geodesic import Geodesic

A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
G = Geodesic.WGS84


def ecef(lon, lat, h):
    phi, lam = math.radians(lat), math.radians(lon)
    n = A / math.sqrt(1 - E2 * math.sin(phi) ** 2)
    return ((n + h) * math.cos(phi) * math.cos(lam),
            (n + h) * math.cos(phi) * math.sin(lam),
            (n * (1 - E2) + h) * math.sin(phi))


def psi(lat):
    e = math.sqrt(E2)
    phi = math.radians(lat)
    return math.asinh(math.tan(phi)) - e * math.atanh(e * math.sin(phi))


def geodesic_dev(p):
    (lon1, lat1), (lon2, lat2) = p["a"], p["b"]
    azi = G.Inverse(lat1, lon1, lat2, lon2)["azi1"]
    worst = 0.0
    for lon, lat, h in p["mids"]:
        s = G.Inverse(lat1, lon1, lat, lon)["s12"]
        q = G.Direct(lat1, lon1, azi, s)
        d = math.dist(ecef(q["lon2"], q["lat2"], p["h"]), ecef(lon, lat, h))
        worst = max(worst, d)
    return worst


def rhumb_dev(p):
    (lon1, lat1), (lon2, lat2) = p["a"], p["b"]
    dlon = (lon2 - lon1 + 540) % 360 - 180
    dpsi = psi(lat2) - psi(lat1)
    worst = 0.0
    for lon, lat, h in p["mids"]:
        if abs(dpsi) < 1e-15:
            d = abs(lat - lat1) * 111_000.0
        else:
            lam = lon1 + (psi(lat) - psi(lat1)) / dpsi * dlon
            dl = (lon - lam + 540) % 360 - 180
            n = A / math.sqrt(1 - E2 * math.sin(math.radians(lat)) ** 2)
            # Distance along the parallel, then its part across the line (the Mercator
            # projection is conformal, so the bearing there is atan2(dlon, dpsi)).
            along = abs(math.radians(dl)) * n * math.cos(math.radians(lat))
            d = along * abs(math.cos(math.atan2(math.radians(dlon), dpsi)))
        worst = max(worst, math.hypot(d, h - p["h"]))
    return worst


paths = json.load(sys.stdin)
print(json.dumps([geodesic_dev(p) if p["kind"] == "geodesic" else rhumb_dev(p) for p in paths]))
