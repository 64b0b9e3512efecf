//! Label placement and decluttering per frame: 4,000 data blocks (16,000 to see how it
//! grows) moving over a 1920x1080 view, as `TrafficLayer` asks for them; and laying out one
//! data block's glyphs.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use globus_engine::labels::{LabelPlacer, LabelRequest};
use globus_engine::text::GlyphAtlas;

fn requests(n: usize) -> Vec<LabelRequest> {
    // A fixed scatter (golden-ratio sequences), data blocks of 3 lines of 8 characters.
    (0..n)
        .map(|i| {
            let f = i as f32;
            LabelRequest {
                id: i as u64,
                anchor_px: [
                    (f * 0.618_034).fract() * 1920.0,
                    (f * 0.754_878).fract() * 1080.0,
                ],
                clearance_px: 11.0,
                size_px: [58.0, 42.0],
                priority: (f * 0.569_840).fract(),
            }
        })
        .collect()
}

fn placement(c: &mut Criterion) {
    for n in [30usize, 4_000, 16_000] {
        let mut reqs = requests(n);
        // Every aircraft's symbol, 18 px square, is an obstacle.
        let symbols: Vec<[f32; 4]> = reqs
            .iter()
            .map(|r| {
                let [x, y] = r.anchor_px;
                [x - 9.0, y - 9.0, x + 9.0, y + 9.0]
            })
            .collect();
        let mut placer = LabelPlacer::new(0.3);
        let mut out = Vec::new();
        placer.place(&reqs, &symbols, [1920.0, 1080.0], 1.0 / 30.0, &mut out);
        c.bench_function(&format!("place {n} moving labels"), |b| {
            b.iter(|| {
                for r in reqs.iter_mut() {
                    r.anchor_px[0] = (r.anchor_px[0] + 0.7) % 1920.0;
                }
                placer.place(
                    black_box(&reqs),
                    &symbols,
                    [1920.0, 1080.0],
                    1.0 / 30.0,
                    &mut out,
                );
                black_box(out.len())
            })
        });
    }
    let atlas = GlyphAtlas::new().expect("font");
    c.bench_function("lay out a 3-line data block", |b| {
        b.iter(|| {
            let mut n = 0;
            atlas.layout(
                black_box(["SWR123", "FL350\u{2191}", "452kt"]),
                14.0,
                |_, _, _| n += 1,
            );
            n
        })
    });
}

criterion_group!(benches, placement);
criterion_main!(benches);
