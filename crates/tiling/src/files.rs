//! Files from outside, read without trusting them.
//!
//! Every reader of tiles, archives, rasters, metadata and configs opens through here, so that
//! one rule holds everywhere: only regular files are read (a FIFO would block a loader thread
//! for ever, `/dev/zero` never ends), opened non-blocking so that a FIFO swapped in after the
//! check cannot block either, and never more bytes than the caller's cap, checked against the
//! file's size before anything is allocated and enforced while reading (a file may grow).
//!
//! Outputs are written whole or not at all: to a temporary file beside the target, synced and
//! renamed over it, so that a full disk or a crash never leaves a truncated PNG or mesh, and a
//! failed run leaves an existing file as it was (the temporary is `NAME.partial`, as the
//! tiler's archives are). Only regular files are replaced (as root,
//! `--out /dev/null` must not replace the device).

use std::fs::File;
use std::io::{Error, ErrorKind, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

/// The largest tile read from any container (a directory, an MBTiles or PMTiles archive, a
/// disk cache), in bytes: a tile is a few hundred KiB at most.
pub const MAX_TILE_BYTES: u64 = 64 << 20;

/// The largest text file read (a `metadata.json`, a config, a camera path), in bytes.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Opens `path` for reading if it is a regular file (symbolic links followed); a FIFO, device,
/// socket or directory is refused with [`ErrorKind::InvalidInput`].
pub fn open_regular(path: &Path) -> std::io::Result<File> {
    let not_regular = || {
        Error::new(
            ErrorKind::InvalidInput,
            "not a regular file (a directory, FIFO, device or socket)",
        )
    };
    if !std::fs::metadata(path)?.is_file() {
        return Err(not_regular());
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    // The path may have been replaced between the check and the open.
    if !file.metadata()?.is_file() {
        return Err(not_regular());
    }
    Ok(file)
}

/// The whole of the regular file `path`, refused with [`ErrorKind::InvalidData`] when it holds
/// more than `cap` bytes.
pub fn read_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    let file = open_regular(path)?;
    let len = file.metadata()?.len();
    let too_big = |len: u64| {
        Error::new(
            ErrorKind::InvalidData,
            format!("{len} bytes or more, above the {cap}-byte limit for this kind of file"),
        )
    };
    if len > cap {
        return Err(too_big(len));
    }
    let mut out = Vec::with_capacity(len as usize);
    file.take(cap + 1).read_to_end(&mut out)?;
    if out.len() as u64 > cap {
        return Err(too_big(out.len() as u64));
    }
    Ok(out)
}

/// [`read_capped`] as UTF-8 text.
pub fn read_text_capped(path: &Path, cap: u64) -> std::io::Result<String> {
    String::from_utf8(read_capped(path, cap)?)
        .map_err(|_| Error::new(ErrorKind::InvalidData, "not UTF-8 text"))
}

/// The folder `path` is in (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// Refuses to replace what is not a regular file (a directory, a device, a FIFO).
fn check_replaceable(path: &Path) -> std::io::Result<()> {
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(Error::new(
            ErrorKind::InvalidInput,
            "exists and is not a regular file; refusing to replace it",
        )),
        _ => Ok(()),
    }
}

/// Whether `path` can be written by [`write_atomic`]: its folder takes a new file and the
/// path is not something other than a regular file. Nothing is left behind.
pub fn check_writable(path: &Path) -> std::io::Result<()> {
    check_replaceable(path)?;
    let probe = temporary_beside(path)?;
    if probe.symlink_metadata().is_ok() {
        // Left by a run that stopped: write_atomic replaces it.
        return std::fs::OpenOptions::new()
            .write(true)
            .open(&probe)
            .map(drop);
    }
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)
}

fn temporary_beside(path: &Path) -> std::io::Result<std::path::PathBuf> {
    let name = path
        .file_name()
        .ok_or_else(|| Error::new(ErrorKind::InvalidInput, "names no file"))?;
    // The tiler's convention: `world.pmtiles` is written as `world.pmtiles.partial`.
    Ok(folder_of(path).join(format!("{}.partial", name.to_string_lossy())))
}

/// Writes `bytes` to `path` whole or not at all (a temporary file beside it, synced, renamed
/// over it); on failure `path` is as it was and no temporary file is left.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    check_replaceable(path)?;
    let tmp = temporary_beside(path)?;
    let result = (|| {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Whether two paths name the same file, existing or not (`out.png` and `./out.png`).
pub fn same_file(a: &Path, b: &Path) -> bool {
    let resolve = |p: &Path| {
        p.canonicalize()
            .ok()
            .or_else(|| Some(folder_of(p).canonicalize().ok()?.join(p.file_name()?)))
    };
    match (resolve(a), resolve(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("globus-files-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A FIFO, `/dev/zero` and a directory are refused at once (a FIFO would block, the
    /// device never ends); regular files under the cap are read whole.
    #[test]
    fn only_regular_files_are_read_and_never_more_than_the_cap() {
        let d = scratch("kinds");
        let fifo = d.join("fifo.png");
        globus_test_support::mkfifo(&fifo);
        for p in [fifo.as_path(), Path::new("/dev/zero"), d.as_path()] {
            let e = read_capped(p, 1 << 20).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidInput, "{}: {e}", p.display());
        }
        let f = d.join("tile.png");
        std::fs::write(&f, vec![7u8; 1000]).unwrap();
        assert_eq!(read_capped(&f, 1000).unwrap().len(), 1000);
        let e = read_capped(&f, 999).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidData);
        assert!(e.to_string().contains("999-byte limit"), "{e}");
        // A sparse 6 GB file is refused from its size, before anything is read.
        let sparse = d.join("big.terrain");
        let file = File::create(&sparse).unwrap();
        file.set_len(6 << 30).unwrap();
        assert_eq!(
            read_capped(&sparse, MAX_TILE_BYTES).unwrap_err().kind(),
            ErrorKind::InvalidData
        );
        std::fs::remove_dir_all(&d).ok();
    }

    /// A failed write leaves the old file whole and no temporary behind; a device is never
    /// replaced; `./x` and `x` are one file.
    #[test]
    fn writes_are_whole_or_nothing() {
        let d = scratch("atomic");
        let f = d.join("frame.png");
        write_atomic(&f, b"old picture").unwrap();
        write_atomic(&f, b"new picture").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"new picture");
        // A write that cannot finish (its folder is gone): the target is untouched.
        let gone = d.join("missing").join("frame.png");
        assert!(write_atomic(&gone, b"x").is_err());
        assert!(check_writable(&gone).is_err());
        assert!(check_writable(&f).is_ok());
        let e = write_atomic(Path::new("/dev/null"), b"x").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidInput);
        assert!(check_writable(Path::new("/dev/null")).is_err());
        let left: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(left, [std::ffi::OsString::from("frame.png")]);
        assert!(same_file(&f, &d.join(".").join("frame.png")));
        assert!(same_file(&d.join("new.json"), &d.join("./new.json")));
        assert!(!same_file(&f, &d.join("frame.json")));
        std::fs::remove_dir_all(&d).ok();
    }
}
