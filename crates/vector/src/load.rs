//! [`load_file`]: a whole file read into [`Feature`]s, every problem a [`FeatureWarning`]
//! naming the feature, and logged (the first [`LOGGED_WARNINGS`] in full, then a count, so a
//! file of a million bad features does not flood the log or memory).

use std::path::{Path, PathBuf};

use crate::feature::{Feature, from_geojson};
use crate::read::{Flow, ReadError, read_file};
use crate::style::StyleRules;

/// Warnings logged and kept per file; the rest are counted.
pub const LOGGED_WARNINGS: usize = 20;

/// A problem with one feature.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FeatureWarning {
    /// The feature's index in its file.
    pub index: usize,
    /// What is wrong (and what was done about it).
    pub message: String,
}

/// What a file gave.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Loaded {
    /// The file.
    pub path: PathBuf,
    /// The features with something to draw.
    pub features: Vec<Feature>,
    /// Features in the file, drawable or not.
    pub read: usize,
    /// The first [`LOGGED_WARNINGS`] warnings.
    pub warnings: Vec<FeatureWarning>,
    /// All warnings, kept or not.
    pub warning_count: usize,
    /// Why the read ended early, if it did.
    pub stopped: Option<String>,
}

/// Reads and styles the features of `path`, as many as hold at most `max_positions`
/// positions together: the read stops, with a warning and [`Loaded::stopped`] saying so, at
/// the first feature that would take more (the features before it are kept).
pub fn load_file(
    path: &Path,
    rules: &StyleRules,
    max_positions: usize,
) -> Result<Loaded, ReadError> {
    let mut loaded = Loaded {
        path: path.to_owned(),
        ..Default::default()
    };
    let mut messages = Vec::new();
    let mut positions = 0usize;
    let summary = read_file(path, &mut |index, raw| {
        messages.clear();
        match raw {
            Ok(f) => {
                if let Some(f) = from_geojson(index, f, rules, &mut messages) {
                    positions += f.position_count();
                    if positions > max_positions {
                        return Flow::Break(format!(
                            "feature {index} would take the layer past {max_positions} \
                             positions, the most it may hold"
                        ));
                    }
                    loaded.features.push(f);
                }
            }
            Err(e) => messages.push(format!("{e} (left out)")),
        }
        for message in messages.drain(..) {
            loaded.warning_count += 1;
            if loaded.warnings.len() < LOGGED_WARNINGS {
                tracing::warn!("{}: feature {index}: {message}", path.display());
                loaded.warnings.push(FeatureWarning { index, message });
            }
        }
        Flow::Continue(())
    })?;
    loaded.read = summary.features;
    if loaded.warning_count > LOGGED_WARNINGS {
        tracing::warn!(
            "{}: {} more warnings not shown",
            path.display(),
            loaded.warning_count - LOGGED_WARNINGS
        );
    }
    if let Some(why) = &summary.stopped {
        tracing::warn!(
            "{}: reading stopped ({why}); the {} drawable features before it are kept",
            path.display(),
            loaded.features.len()
        );
    }
    loaded.stopped = summary.stopped;
    Ok(loaded)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::style::Clamp;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data")
            .join(name)
    }

    /// Mutated GeoJSON, sequences and airspaces: read, checked, styled, densified,
    /// tessellated and draped without a panic.
    #[test]
    fn fuzz_geojson() {
        use crate::shape::{self, Straight};
        let ellipsoid = globus_geo::Ellipsoid::WGS84;
        let surface = crate::DrapeSurface::new(
            [-10.0, -10.0, 10.0, 10.0],
            vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
            vec![
                globus_geo::DVec3::ZERO,
                globus_geo::DVec3::X,
                globus_geo::DVec3::Y,
            ],
            vec![[0, 1, 2]],
        );
        let r = globus_test_support::fuzz::run("geojson", |b| {
            let mut any = false;
            let _ = crate::read::read(Path::new("fuzz.geojson"), b, &mut |i, raw| -> Flow {
                let Ok(f) = raw else {
                    return Flow::Continue(());
                };
                let mut w = Vec::new();
                let Some(f) = crate::from_geojson(i, f, &StyleRules::default(), &mut w) else {
                    return Flow::Continue(());
                };
                any = true;
                for l in &f.lines {
                    let d =
                        shape::densify(&ellipsoid, l, false, f.style.path, Straight::Chord, 1000.0);
                    let pts: Vec<[f64; 2]> = d.iter().map(|p| [p[0], p[1]]).collect();
                    surface.drape_line(&pts, 0.0, &mut Vec::new());
                }
                for p in &f.polygons {
                    for t in shape::tessellate(p, 5.0).into_iter().take(1000) {
                        surface.drape_triangle(t, 0.0, &mut Vec::new());
                    }
                }
                Flow::Continue(())
            });
            any
        });
        assert!(
            r.cases > 0 && r.accepted > 0 && r.accepted < r.cases,
            "{r:?}"
        );
    }

    #[test]
    fn every_country_loads_without_a_warning() {
        let l = load_file(
            &data("countries-110m.geojson"),
            &StyleRules::default(),
            usize::MAX,
        )
        .unwrap();
        assert_eq!(l.read, 177);
        assert_eq!(l.features.len(), 177);
        // Natural Earth's 1:110m USA (Alaska, at 141 W) and Sudan rings cross themselves by
        // a few metres: warned about, drawn all the same.
        let crossing: Vec<usize> = l.warnings.iter().map(|w| w.index).collect();
        assert_eq!(crossing, [4, 14]);
        assert!(
            l.warnings
                .iter()
                .all(|w| w.message.contains("crosses itself"))
        );
        let antarctica = l
            .features
            .iter()
            .find(|f| f.properties["name"] == "Antarctica")
            .unwrap();
        assert!(
            antarctica
                .polygons
                .iter()
                .any(|p| p[0].iter().any(|q| q[1] == -90.0))
        );
    }

    #[test]
    fn every_fir_extrudes_to_its_own_limits() {
        let rules = StyleRules::from_fragment("extrude=true").unwrap();
        let l = load_file(&data("eurocontrol-firs.geojson"), &rules, usize::MAX).unwrap();
        assert_eq!(l.read, 58);
        assert_eq!(l.features.len(), 58, "{:?}", l.warnings);
        for f in &l.features {
            let (lo, hi) = f
                .style
                .extrude
                .unwrap_or_else(|| panic!("{:?}", f.properties));
            assert!(
                lo >= 0.0 && hi > lo && hi <= 999.0 * 100.0 * crate::style::FOOT_M,
                "{lo} {hi}"
            );
            assert_eq!(f.style.clamp, Clamp::Absolute);
        }
    }

    #[test]
    fn the_toulouse_airspace_reads_in_flight_levels() {
        let l = load_file(
            &data("airspace-LFBOTMA.json"),
            &StyleRules::default(),
            usize::MAX,
        )
        .unwrap();
        assert!(l.features.len() >= 2, "{}", l.features.len());
        assert_eq!(l.warnings, []);
        let (lo, hi) = l.features[0].style.extrude.unwrap();
        assert_eq!((lo, hi), (0.0, 6500.0 * crate::style::FOOT_M));
    }

    #[test]
    fn bad_features_are_each_named_and_the_rest_kept() {
        let dir = std::env::temp_dir().join(format!("globus-vector-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.geojson");
        let mut text = String::from(r#"{"type": "FeatureCollection", "features": ["#);
        let good = r#"{"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [1, 2]}}"#;
        let bad = [
            r#"{"type": "Feature", "properties": {}, "geometry": {"type": "Circle", "coordinates": [1, 2]}}"#,
            r#"{"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": ["a", 2]}}"#,
            r#"{"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1]]]}}"#,
            r#"{"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": [[0, 0], [0, 95]]}}"#,
        ];
        for k in 0..100 {
            if k > 0 {
                text.push(',');
            }
            text.push_str(if k % 10 == 3 { bad[k / 10 % 4] } else { good });
        }
        text.push_str("]}");
        std::fs::write(&path, text).unwrap();
        let l = load_file(&path, &StyleRules::default(), usize::MAX).unwrap();
        assert_eq!(l.read, 100);
        assert_eq!(l.features.len(), 90);
        assert_eq!(l.warning_count, 10);
        assert_eq!(
            l.warnings.iter().map(|w| w.index).collect::<Vec<_>>(),
            (0..10).map(|k| k * 10 + 3).collect::<Vec<_>>()
        );
        let e = load_file(
            &dir.join("missing.geojson"),
            &StyleRules::default(),
            usize::MAX,
        )
        .unwrap_err();
        assert!(e.to_string().contains("missing.geojson"), "{e}");
        std::fs::write(&path, "name,lat,lon\nx,1,2\n").unwrap();
        let e = load_file(&path, &StyleRules::default(), usize::MAX).unwrap_err();
        assert!(e.to_string().contains("not GeoJSON"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_file_stops_at_the_feature_that_would_pass_the_position_budget() {
        let dir = std::env::temp_dir().join(format!("globus-vector-cap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let line = |k: usize| {
            let coords: Vec<String> = (0..10).map(|i| format!("[{}, {}]", i, k % 80)).collect();
            format!(
                r#"{{"type": "Feature", "properties": {{}}, "geometry": {{"type": "LineString", "coordinates": [{}]}}}}"#,
                coords.join(",")
            )
        };
        let features: Vec<String> = (0..100).map(line).collect();
        let collection = dir.join("lines.geojson");
        std::fs::write(
            &collection,
            format!(
                r#"{{"type": "FeatureCollection", "features": [{}]}}"#,
                features.join(",")
            ),
        )
        .unwrap();
        let sequence = dir.join("lines.geojsonl");
        let records: String = features.iter().map(|f| format!("\x1e{f}\n")).collect();
        std::fs::write(&sequence, records).unwrap();
        for path in [&collection, &sequence] {
            let l = load_file(path, &StyleRules::default(), 255).unwrap();
            // 25 lines of 10 positions fit; the 26th would make 260.
            assert_eq!(l.features.len(), 25, "{}", path.display());
            assert_eq!(l.read, 26, "{}: read no further", path.display());
            let why = l.stopped.expect("stopped");
            assert!(
                why.contains("feature 25") && why.contains("255 positions"),
                "{why}"
            );
            let all = load_file(path, &StyleRules::default(), 1000).unwrap();
            assert_eq!((all.features.len(), all.stopped), (100, None));
        }
    }
}
