//! `globus tile` as a user runs it: a JSON summary on success, one clear line naming the
//! file and the problem for every bad input.

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

mod common;
use common::{fails_with_one_line, globus, s};
use std::process::Command;

fn scratch(name: &str) -> std::path::PathBuf {
    common::scratch("tile_cli", name)
}

#[test]
fn dem_prints_a_json_summary() {
    let dir = scratch("summary");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let out = dir.join("pyramid.mbtiles");
    let o = globus(&[
        "tile",
        "dem",
        "--in",
        s(&hgt),
        "--out",
        s(&out),
        "--scheme",
        "webmercator",
        "--encoding",
        "mapbox",
        "--max-level",
        "9",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // Mercator levels 0..9 over 11..12 E, 57..58 N (closed footprint): 1+1+1+1+1+2+2+4+4+9.
    assert_eq!(v["tiles"], 26, "{v}");
    assert!(v["bytes"].as_u64().unwrap() > 10_000);
    assert!(v["tiles_per_second"].as_f64().unwrap() > 0.0);
    assert!(v["seconds"].as_f64().is_some());
    // The output exists now: a second run must refuse, --force replaces it.
    fails_with_one_line(
        &["tile", "dem", "--in", s(&hgt), "--out", s(&out)],
        &["pyramid.mbtiles", "already exists", "--force"],
    );
    let o = globus(&[
        "tile",
        "dem",
        "--in",
        s(&hgt),
        "--out",
        s(&out),
        "--force",
        "--max-level",
        "3",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn bad_inputs_end_with_one_line_naming_the_file() {
    let dir = scratch("bad");
    let out = dir.join("out");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let truncated = dir.join("N10E020.hgt");
    std::fs::write(&truncated, vec![0u8; 4000]).unwrap();
    let corrupt = dir.join("world.jpg");
    std::fs::write(&corrupt, b"\xff\xd8\xff\xe0 this is not really a JPEG").unwrap();
    let badname = dir.join("elevation.hgt");
    std::fs::copy(&hgt, &badname).unwrap();
    let text = dir.join("notes.txt");
    std::fs::write(&text, "hello").unwrap();
    let missing = dir.join("N00E000.hgt");
    let grey = globus_test_support::shared_data("earth-topology-2048x1024.png");
    // A FIFO would block the reader for ever; /dev/zero (behind a link) never ends.
    let fifo = dir.join("world-fifo.jpg");
    globus_test_support::mkfifo(&fifo);
    let zero = dir.join("zero.jpg");
    let _ = std::fs::remove_file(&zero);
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["dem", "--in", s(&truncated)],
            vec!["N10E020.hgt", "truncated"],
        ),
        (
            vec!["imagery", "--in", s(&corrupt)],
            vec!["world.jpg", "decode"],
        ),
        (
            vec!["dem", "--in", s(&badname)],
            vec!["elevation.hgt", "N57E011"],
        ),
        (
            vec!["dem", "--in", s(&text)],
            vec!["notes.txt", "unknown input type"],
        ),
        (
            vec!["dem", "--in", s(&missing)],
            vec!["N00E000.hgt", "No such file"],
        ),
        (
            vec!["dem", "--in", s(&grey)],
            vec!["earth-topology-2048x1024.png", "--height-scale"],
        ),
        (
            vec!["dem", "--in", s(&grey), "--height-scale", "1e30"],
            vec!["--height-scale", "1e30"],
        ),
        (
            vec!["imagery", "--in", s(&fifo)],
            vec!["world-fifo.jpg", "not a regular file"],
        ),
        (
            vec!["imagery", "--in", s(&zero)],
            vec!["zero.jpg", "not a regular file"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--shard", "0/4000000000"],
            vec!["--shard", "4000000000", "10000"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--bounds", "0,0,1,1"],
            vec!["does not intersect --bounds"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--bounds", "10,60,5,50"],
            vec!["--bounds"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--bounds", "1,2,3"],
            vec!["--bounds", "four numbers"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--tile-size", "300"],
            vec!["--tile-size"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--encoding", "float"],
            vec!["float", "terrarium"],
        ),
        (
            vec!["dem", "--in", s(&hgt), "--scheme", "utm"],
            vec!["utm", "geographic"],
        ),
        (
            vec!["imagery", "--in", s(&hgt)],
            vec!["N57E011.hgt", "tile dem"],
        ),
        (
            vec!["imagery", "--in", s(&corrupt), "--format", "gif"],
            vec!["gif"],
        ),
        (
            vec![
                "dem",
                "--in",
                s(&hgt),
                "--min-level",
                "5",
                "--max-level",
                "3",
            ],
            vec!["--max-level"],
        ),
    ];
    for (args, needles) in cases {
        let mut full = vec!["tile"];
        full.extend(args);
        full.extend(["--out", s(&out)]);
        fails_with_one_line(&full, &needles);
        assert!(!out.exists(), "{full:?} left an output behind");
    }
    // An output that cannot be written.
    fails_with_one_line(
        &[
            "tile",
            "dem",
            "--in",
            s(&hgt),
            "--out",
            "/proc/globus-cannot-write-here",
            "--max-level",
            "2",
        ],
        &["/proc/globus-cannot-write-here"],
    );
}

#[test]
fn force_will_not_delete_a_directory_that_is_not_a_pyramid() {
    let dir = scratch("force");
    std::fs::write(dir.join("thesis.tex"), "precious").unwrap();
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    fails_with_one_line(
        &["tile", "dem", "--in", s(&hgt), "--out", s(&dir), "--force"],
        &["thesis.tex", "not part of a tile pyramid"],
    );
    assert!(dir.join("thesis.tex").exists());
}

#[test]
fn plan_shards_by_environment_and_merge() {
    let dir = scratch("shards");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let common = [
        "--in",
        s(&hgt),
        "--scheme",
        "webmercator",
        "--max-level",
        "10",
    ];
    let mut args = vec!["tile", "plan", "--shards", "2", "dem"];
    args.extend(common);
    args.extend(["--out", "unused"]);
    let o = globus(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let plan: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(plan["shards"].as_array().unwrap().len(), 2, "{plan}");
    let total = plan["total_tiles"].as_u64().unwrap();
    // Shard indices from the schedulers' environment variables.
    let parts = [dir.join("k8s"), dir.join("slurm")];
    let envs = [("JOB_COMPLETION_INDEX", "0"), ("SLURM_ARRAY_TASK_ID", "1")];
    for (part, (var, value)) in parts.iter().zip(envs) {
        let mut args = vec!["tile", "dem"];
        args.extend(common);
        args.extend(["--shard", "2", "--out", s(part)]);
        let o = Command::new(env!("CARGO_BIN_EXE_globus"))
            .args(&args)
            .env_remove("JOB_COMPLETION_INDEX")
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("SLURM_ARRAY_TASK_MIN")
            .env(var, value)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let merged = dir.join("merged.mbtiles");
    let o = globus(&[
        "tile",
        "merge",
        "--in",
        s(&parts[0]),
        s(&parts[1]),
        "--out",
        s(&merged),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["tiles"].as_u64().unwrap(), total, "{v}");
    // Merging one shard alone, or something that is not a shard, is refused.
    fails_with_one_line(
        &[
            "tile",
            "merge",
            "--in",
            s(&parts[1]),
            "--out",
            s(&dir.join("half.mbtiles")),
        ],
        &["shards 0 of 2 are missing"],
    );
    fails_with_one_line(
        &[
            "tile",
            "merge",
            "--in",
            s(&hgt),
            "--out",
            s(&dir.join("bad.mbtiles")),
        ],
        &["N57E011.hgt", "not a finished shard output"],
    );
    fails_with_one_line(
        &[
            "tile",
            "dem",
            "--in",
            s(&hgt),
            "--shard",
            "3/2",
            "--out",
            s(&dir.join("x")),
        ],
        &["--shard"],
    );
}

#[test]
fn a_full_disk_ends_with_one_line_and_no_finished_archive() {
    let dir = scratch("full");
    let out = dir.join("world.pmtiles");
    // Tile data goes to world.pmtiles.partial first: point it at /dev/full, a device that
    // answers every write with "no space left on device".
    std::os::unix::fs::symlink("/dev/full", dir.join("world.pmtiles.partial")).unwrap();
    let bmng = globus_test_support::shared_data("bmng-5400x2700.jpg");
    fails_with_one_line(
        &[
            "tile",
            "imagery",
            "--in",
            s(&bmng),
            "--out",
            s(&out),
            "--max-level",
            "1",
        ],
        &["world.pmtiles.partial", "No space left on device"],
    );
    assert!(
        !out.exists(),
        "a failed run left a finished-looking archive"
    );
}

/// `--shards 4000000000` aborted on a 96 GB allocation: refused with the largest count.
#[test]
fn plan_refuses_more_shards_than_it_can_share_out() {
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    for n in ["4000000000", "1000000", "0"] {
        fails_with_one_line(
            &[
                "tile",
                "plan",
                "--shards",
                n,
                "dem",
                "--in",
                s(&hgt),
                "--out",
                "unused",
            ],
            &["--shards", n],
        );
    }
}

/// `--threads 10000` was still running at 60 s (0.06 s with the default): capped, with a note.
#[test]
fn ten_thousand_threads_are_capped_with_a_note() {
    let dir = scratch("threads");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let out = dir.join("p");
    let _ = std::fs::remove_dir_all(&out);
    let o = globus(&[
        "tile",
        "dem",
        "--in",
        s(&hgt),
        "--out",
        s(&out),
        "--max-level",
        "4",
        "--threads",
        "10000",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("--threads 10000: using"), "{err}");
}

/// `tile --force` deleted any non-directory at the output path (a text file; as root,
/// `/dev/null`): it replaces only its own kind of output, recognised by its first bytes.
#[test]
fn force_replaces_only_its_own_kind_of_output() {
    let dir = scratch("force-kinds");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let notes = dir.join("notes.mbtiles");
    std::fs::write(&notes, "not a database").unwrap();
    let plain = dir.join("pyramid");
    std::fs::write(&plain, "a text file where a pyramid directory would go").unwrap();
    let fifo = dir.join("pipe.pmtiles");
    globus_test_support::mkfifo(&fifo);
    for (out, needle) in [
        (&notes, "not an MBTILES archive"),
        (&plain, "not a directory"),
        (&fifo, "not a regular file"),
    ] {
        fails_with_one_line(
            &[
                "tile",
                "dem",
                "--in",
                s(&hgt),
                "--out",
                s(out),
                "--force",
                "--max-level",
                "2",
            ],
            &["--force refuses", needle],
        );
        assert!(
            out.symlink_metadata().is_ok(),
            "{} was deleted",
            out.display()
        );
    }
    assert_eq!(std::fs::read(&notes).unwrap(), b"not a database");
    // Its own archive is replaced.
    let own = dir.join("own.mbtiles");
    for _ in 0..2 {
        let o = globus(&[
            "tile",
            "dem",
            "--in",
            s(&hgt),
            "--out",
            s(&own),
            "--force",
            "--max-level",
            "2",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
}

/// Two runs writing one MBTiles both ran to the end and the second then failed with "disk I/O
/// error": the second is refused at once while the first holds the output.
#[test]
fn a_second_run_on_a_busy_output_is_refused_at_once() {
    let dir = scratch("lock");
    let hgt = globus_test_support::shared_data("N57E011.hgt");
    let out = dir.join("busy.mbtiles");
    // The first run's hold, taken here as `globus tile` takes it.
    let lock = std::fs::File::create(dir.join("busy.mbtiles.lock")).unwrap();
    lock.try_lock().unwrap();
    fails_with_one_line(
        &[
            "tile",
            "dem",
            "--in",
            s(&hgt),
            "--out",
            s(&out),
            "--max-level",
            "2",
        ],
        &["busy.mbtiles", "another globus tile is writing it"],
    );
    assert!(!out.exists());
    drop(lock);
    let o = globus(&[
        "tile",
        "dem",
        "--in",
        s(&hgt),
        "--out",
        s(&out),
        "--max-level",
        "2",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        !dir.join("busy.mbtiles.lock").exists(),
        "the lock file is left behind"
    );
}

/// `--night-imagery` takes a tiled pyramid as well as one image: NASA's night lights tiled
/// by `globus tile imagery` (lossless PNG, geographic) light Europe's night exactly as the
/// image itself does, a Web Mercator tiling of it within its double resampling, and a
/// pyramid that is not there is named in one line.
#[test]
fn night_imagery_from_a_tiled_pyramid_lights_the_night_as_the_image_does() {
    let dir = scratch("night");
    let jpg = globus_test_support::shared_data("earth-night-4096x2048.jpg");
    let render = |night: &str, name: &str| -> image::RgbImage {
        let out = dir.join(format!("{name}.png"));
        let o = globus(&[
            "render",
            "--camera",
            "10,48,3000000,0,-90",
            "--size",
            "240x135",
            "--time",
            "2026-06-21T23:00:00Z",
            "--night-imagery",
            night,
            "--out",
            s(&out),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        image::open(&out).unwrap().to_rgb8()
    };
    let from_image = render(s(&jpg), "image");
    // Lights: warm pixels brighter than the night around them.
    let lit = from_image
        .pixels()
        .filter(|p| p[0] > 120 && p[0] > p[2])
        .count();
    assert!(lit > 200, "only {lit} lit pixels over Europe at night");
    for (scheme, tolerance) in [("geographic", 0.0), ("webmercator", 2.0)] {
        let pyramid = dir.join(scheme);
        let o = globus(&[
            "tile",
            "imagery",
            "--in",
            s(&jpg),
            "--out",
            s(&pyramid),
            "--format",
            "png",
            "--scheme",
            scheme,
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let from_tiles = render(s(&pyramid), scheme);
        let diff: f64 = from_tiles
            .as_raw()
            .iter()
            .zip(from_image.as_raw())
            .map(|(a, b)| f64::from(a.abs_diff(*b)))
            .sum::<f64>()
            / from_image.as_raw().len() as f64;
        assert!(
            diff <= tolerance,
            "{scheme}: mean difference {diff:.3} from the image's picture"
        );
    }
    let missing = dir.join("no-such-pyramid");
    fails_with_one_line(
        &[
            "render",
            "--camera",
            "0,0,1000,0,0",
            "--size",
            "64x64",
            "--out",
            s(&dir.join("x.png")),
            "--night-imagery",
            s(&missing),
        ],
        &["night imagery", "no-such-pyramid"],
    );
}
