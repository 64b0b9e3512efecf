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
