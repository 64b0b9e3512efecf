//! Tiles in a local directory tree named by a template (`{z}/{x}/{y}.png`, TMS or quadkeys).
//!
//! The template must be relative and free of `..`; only numbers and quadkey digits are
//! substituted into it; and every file is resolved (symbolic links included) and refused if
//! it lies outside the root. A missing file is "no data here".

use std::io::ErrorKind;
use std::path::{Component, Path, PathBuf};

use globus_tiling::{TileKey, TilingScheme};

use super::{Cancel, Fetch, FetchError, Fetched, OpenError, UrlTemplate};

use globus_tiling::files::MAX_TILE_BYTES;

/// Reads tiles from a directory.
pub struct DirectoryFetch {
    root: PathBuf,
    template: UrlTemplate,
    scheme: TilingScheme,
    name: String,
}

impl DirectoryFetch {
    /// Tiles of `scheme` under `root`, named by `template` relative to it.
    pub fn new(root: &Path, template: &str, scheme: TilingScheme) -> Result<Self, OpenError> {
        let root = root.canonicalize().map_err(|e| {
            OpenError::Unreadable(format!("tile directory {}: {e}", root.display()))
        })?;
        let t = Path::new(template);
        if t.is_absolute()
            || t.components()
                .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
        {
            return Err(OpenError::Spec(format!(
                "tile path template {template:?} must be relative to {} and must not use '..'",
                root.display()
            )));
        }
        let template = UrlTemplate::parse(template, &[])?;
        let name = root.join(template.as_str()).display().to_string();
        Ok(Self {
            root,
            template,
            scheme,
            name,
        })
    }
}

impl Fetch for DirectoryFetch {
    fn name(&self) -> &str {
        &self.name
    }

    fn locate(&self, key: TileKey) -> String {
        self.root
            .join(self.template.expand(self.scheme, key))
            .display()
            .to_string()
    }

    fn fetch(&self, key: TileKey, _cancel: &Cancel) -> Result<Option<Fetched>, FetchError> {
        let path = self.root.join(self.template.expand(self.scheme, key));
        let real = match path.canonicalize() {
            Ok(p) => p,
            Err(e) if e.kind() == ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(FetchError::transient(format!("{}: {e}", path.display()))),
        };
        if !real.starts_with(&self.root) {
            return Err(FetchError::Permanent(format!(
                "{} resolves to {}, outside the tile directory {}",
                path.display(),
                real.display(),
                self.root.display()
            )));
        }
        match globus_tiling::files::read_capped(&real, MAX_TILE_BYTES) {
            Ok(b) if b.is_empty() => Ok(None),
            Ok(b) => Ok(Some(Fetched::local(b))),
            Err(e) if e.kind() == ErrorKind::NotFound => Ok(None),
            // Too big, or a FIFO or device: reading again will not help.
            Err(e) if matches!(e.kind(), ErrorKind::InvalidData | ErrorKind::InvalidInput) => {
                Err(FetchError::Permanent(format!("{}: {e}", path.display())))
            }
            Err(e) => Err(FetchError::transient(format!("{}: {e}", path.display()))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_tiles_and_nothing_outside_the_root() {
        let base = std::env::temp_dir().join(format!("globus-dirfetch-{}", std::process::id()));
        let root = base.join("tiles");
        std::fs::create_dir_all(root.join("3/4")).unwrap();
        std::fs::write(root.join("3/4/2.png"), b"tile").unwrap();
        std::fs::write(base.join("secret.txt"), b"secret").unwrap();
        // A link inside the root that points outside it.
        std::fs::create_dir_all(root.join("4/0")).unwrap();
        std::os::unix::fs::symlink(base.join("secret.txt"), root.join("4/0/0.png")).unwrap();

        let geo = TilingScheme::Geographic;
        let f = DirectoryFetch::new(&root, "{z}/{x}/{y}.png", geo).unwrap();
        let c = Cancel::new();
        let got = f.fetch(TileKey::new(3, 4, 2), &c).unwrap().unwrap();
        assert_eq!(got.bytes, b"tile");
        assert_eq!(f.fetch(TileKey::new(3, 4, 3), &c), Ok(None));
        let escaped = f.fetch(TileKey::new(4, 0, 0), &c).unwrap_err();
        assert!(escaped.to_string().contains("outside the tile directory"));

        for bad in [
            "../{z}/{x}/{y}.png",
            "/etc/{z}/{x}/{y}",
            "a/../../{z}/{x}/{y}",
        ] {
            assert!(DirectoryFetch::new(&root, bad, geo).is_err(), "{bad}");
        }
        // TMS rows: geographic level 3 has 8 rows, so row 2 from the north is 5 from the south.
        std::fs::create_dir_all(root.join("tms/3/4")).unwrap();
        std::fs::write(root.join("tms/3/4/5.png"), b"tms").unwrap();
        let tms = DirectoryFetch::new(&root, "tms/{z}/{x}/{-y}.png", geo).unwrap();
        assert_eq!(
            tms.fetch(TileKey::new(3, 4, 2), &c).unwrap().unwrap().bytes,
            b"tms"
        );
        std::fs::remove_dir_all(&base).unwrap();
    }

    /// A FIFO in a tile directory blocked a loader thread for ever (and the process never
    /// exited); a sparse 6 GB file was read whole. Both fail at once, for good.
    #[test]
    fn fifos_and_oversized_files_fail_at_once() {
        let root = std::env::temp_dir().join(format!("globus-dirfifo-{}", std::process::id()));
        std::fs::create_dir_all(root.join("2/1")).unwrap();
        let fifo = root.join("2/1/1.png");
        globus_test_support::mkfifo(&fifo);
        let big = std::fs::File::create(root.join("2/1/0.png")).unwrap();
        big.set_len(6 << 30).unwrap();
        let f = DirectoryFetch::new(&root, "{z}/{x}/{y}.png", TilingScheme::Geographic).unwrap();
        let c = Cancel::new();
        for (y, needle) in [(1, "not a regular file"), (0, "limit")] {
            match f.fetch(TileKey::new(2, 1, y), &c) {
                Err(FetchError::Permanent(m)) => assert!(m.contains(needle), "{m}"),
                other => panic!(
                    "tile 2/1/{y}: {:?}",
                    other.map(|o| o.map(|f| f.bytes.len()))
                ),
            }
        }
        std::fs::remove_dir_all(&root).unwrap();
    }
}
