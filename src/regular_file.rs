//! Opening a file that must be a regular one: a scene and the files it
//! names, a frame or a light mask to compare. Opening a FIFO blocks, a
//! device (a link to `/dev/zero`) never ends, and a directory fails with an
//! OS message that does not say why; each is refused here, by what it is.

use std::fs::{File, FileType, Metadata};
use std::io;
use std::path::Path;

/// Why [`open`] refused a path.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error("file not found")]
    NotFound,
    #[error("not a regular file (it is {kind})")]
    NotRegular { kind: &'static str },
    #[error("cannot read file: {0}")]
    Io(io::Error),
}

impl From<io::Error> for OpenError {
    fn from(e: io::Error) -> Self {
        match e.kind() {
            io::ErrorKind::NotFound => OpenError::NotFound,
            _ => OpenError::Io(e),
        }
    }
}

/// `path` opened for reading, with its metadata, if it is a regular file
/// (after links). Asked of the path before it is opened (opening a FIFO
/// blocks) and of the file opened (the path may have changed between).
pub fn open(path: &Path) -> Result<(File, Metadata), OpenError> {
    check(&std::fs::metadata(path)?)?;
    let file = File::open(path)?;
    let metadata = file.metadata()?;
    check(&metadata)?;
    Ok((file, metadata))
}

/// Whether a file of `metadata` is a regular one, and if not, what it is.
pub fn check(metadata: &Metadata) -> Result<(), OpenError> {
    if metadata.is_file() {
        Ok(())
    } else {
        Err(OpenError::NotRegular {
            kind: kind(&metadata.file_type()),
        })
    }
}

/// What a file that is not a regular one is, for messages.
fn kind(kind: &FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return "a FIFO";
        }
        if kind.is_char_device() {
            return "a character device";
        }
        if kind.is_block_device() {
            return "a block device";
        }
        if kind.is_socket() {
            return "a socket";
        }
    }
    if kind.is_dir() {
        "a directory"
    } else {
        "neither a file nor a directory"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_regular_file_opens_and_the_others_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f");
        std::fs::write(&file, b"abc").unwrap();
        let (_, metadata) = open(&file).unwrap();
        assert_eq!(metadata.len(), 3);
        let err = open(&dir.path().join("none")).unwrap_err();
        assert_eq!(err.to_string(), "file not found");
        let err = open(dir.path()).unwrap_err();
        assert_eq!(err.to_string(), "not a regular file (it is a directory)");
        #[cfg(unix)]
        {
            let link = dir.path().join("zero");
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            let err = open(&link).unwrap_err();
            assert_eq!(
                err.to_string(),
                "not a regular file (it is a character device)"
            );
        }
    }
}
