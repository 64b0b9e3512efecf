#!/usr/bin/env python3
"""Plots a `globus bench --soak` log (JSON lines) as a PNG: resident memory against the total
memory budget, the loaded-tile cache and its share of the budget, the sources' caches, and tiles
resident on the GPU (right axis, scaled to the pool's capacity). Needs Pillow only.

    python3 tools/plot_soak.py SOAK.jsonl OUT.png
"""
import json
import sys

from PIL import Image, ImageDraw


def main():
    rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
    samples = [r for r in rows if "t_s" in r]
    summary = next((r for r in rows if r.get("summary")), {})
    W, H, L, R, T, B = 1200, 600, 80, 90, 50, 60
    img = Image.new("RGB", (W, H), "white")
    d = ImageDraw.Draw(img)
    t_max = max(r["t_s"] for r in samples) or 1.0
    def val(r, key):
        v = r.get(key)
        return v if isinstance(v, (int, float)) else 0.0

    y_max = max(max(val(r, k) for r in samples) for k in ("rss_mib", "cache_budget_mib", "memory_budget_mib")) * 1.15
    cap = max(r["gpu_capacity"] for r in samples) or 1

    def x(t):
        return L + (W - L - R) * t / t_max

    def y(v, top=y_max):
        return H - B - (H - T - B) * v / top

    d.rectangle([L, T, W - R, H - B], outline="black")
    for i in range(6):
        v = y_max * i / 5
        d.line([L - 5, y(v), L, y(v)], fill="black")
        d.text((8, y(v) - 6), f"{v:.0f} MiB", fill="black")
        g = cap * i / 5
        d.text((W - R + 8, y(g, cap) - 6), f"{g:.0f} tiles", fill="purple")
    for i in range(7):
        t = t_max * i / 6
        d.line([x(t), H - B, x(t), H - B + 5], fill="black")
        d.text((x(t) - 12, H - B + 10), f"{t / 60:.1f} min", fill="black")

    def line(key, colour, top=y_max):
        pts = [(x(r["t_s"]), y(val(r, key), top)) for r in samples]
        d.line(pts, fill=colour, width=2)

    if any(val(r, "memory_budget_mib") > 0 for r in samples):
        line("memory_budget_mib", "red")
    line("cache_budget_mib", "orange")
    line("cache_mib", "green")
    line("source_caches_mib", "grey")
    line("rss_mib", "blue")
    line("gpu_tiles", "purple", cap)
    d.text((L + 10, 12), "resident memory (blue) and the memory budget (red); loaded-tile cache (green) "
           "and its share (orange); sources' caches (grey); GPU tiles (purple, right axis)", fill="black")
    if summary:
        d.text((L + 10, 28), f"{summary['seconds'] / 60:.0f} min, {summary['frames']} frames, "
               f"{summary['loaded']} tiles loaded, {summary['failed']} failed, {summary['retries']} retries, "
               f"max RSS {summary['max_rss_mib']:.0f} MiB"
               + (f" of a {summary['memory_budget_mib']:.0f} MiB budget" if summary.get("memory_budget_mib") else ""),
               fill="black")
    img.save(sys.argv[2])


if __name__ == "__main__":
    main()
