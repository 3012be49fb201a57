//! Reading the files a scene names: the scene file itself, and the local
//! files its URIs name (the loader reads buffers; `render::job` hashes
//! buffers and images too). Only regular files are read, and nothing is
//! fetched from a network. A scene's reads may be confined to a directory
//! (`radcache serve --scenes DIR`: [`confined_file`]); the command line
//! reads wherever the user's file points.

use super::Res;
use std::path::{Path, PathBuf};

/// The bytes of `path`, at most `limit` of them: a FIFO or a device (a
/// link to `/dev/zero`) is refused, as it would block or never end, and a
/// limit keeps a file far longer than needed out of memory.
pub fn read_regular_file(path: &Path, limit: Option<u64>) -> Res<Vec<u8>> {
    use std::io::Read;
    let (file, _) = open_checked(path)?;
    let mut bytes = Vec::new();
    file.take(limit.unwrap_or(u64::MAX))
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read file: {e}"))?;
    Ok(bytes)
}

/// `path` opened to be read a piece at a time (a huge image hashed, never
/// held whole), refused as [`read_regular_file`] refuses it, with the
/// number of bytes it holds as it is opened, at most `limit`: the reader
/// ends there, and whoever reads it can check that it got that many.
/// `None` when nothing is at `path` (nor at the end of a link there).
pub fn open_regular_file(
    path: &Path,
    limit: Option<u64>,
) -> Res<Option<(std::io::Take<std::fs::File>, u64)>> {
    use std::io::Read;
    if std::fs::metadata(path).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound) {
        return Ok(None);
    }
    let (file, meta) = open_checked(path)?;
    let len = meta.len().min(limit.unwrap_or(u64::MAX));
    Ok(Some((file.take(len), len)))
}

/// `path` opened, and its metadata, if it is a regular file
/// ([`crate::regular_file`]).
fn open_checked(path: &Path) -> Res<(std::fs::File, std::fs::Metadata)> {
    crate::regular_file::open(path).map_err(|e| e.to_string())
}

/// The file that a glTF `uri` other than a `data:` URI names, relative to
/// the directory `base` of the file that holds it: `%XX` escapes decoded
/// (glTF URIs are RFC 3986), a `file:` scheme allowed; other schemes (a
/// `http:` URI) are refused, as nothing is fetched.
pub fn uri_file(base: &Path, uri: &str) -> Res<std::path::PathBuf> {
    let path = match uri.split_once(':') {
        Some((scheme, rest)) if is_uri_scheme(scheme) => {
            if !scheme.eq_ignore_ascii_case("file") {
                return Err(format!(
                    "URI '{uri}': only files are read, not '{scheme}:' URIs"
                ));
            }
            file_uri_path(rest).ok_or_else(|| {
                format!("URI '{uri}': only local files are read (its host is not this machine)")
            })?
        }
        _ => uri,
    };
    let decoded = crate::uri::percent_decode(path)
        .ok_or_else(|| format!("URI '{uri}': malformed %-escape or not UTF-8"))?;
    Ok(base.join(decoded))
}

/// The file a glTF `uri` names, as [`uri_file`] resolves it against the
/// directory `base` of the file that holds it, and, when `root` is given,
/// only inside that directory ([`confined_file`]). A refusal names the URI
/// only, neither path: a server must not tell a client where its scenes
/// lie, nor which files outside them exist.
pub fn confined_uri_file(base: &Path, uri: &str, root: Option<&Path>) -> Res<PathBuf> {
    let file = uri_file(base, uri)?;
    match root {
        None => Ok(file),
        Some(root) => confined_file(&file, root).ok_or_else(|| {
            format!("URI '{uri}' names no file inside the directory the scene is confined to")
        }),
    }
}

/// The canonical path of `file` if it lies inside directory `root` once
/// both are canonical, so that neither `..`, an absolute path nor a
/// symbolic link leads out of it; reading that path reads what was
/// checked. A file not there is inside when its directory is (a dangling
/// link is not), so that it is reported missing; `None` otherwise.
pub fn confined_file(file: &Path, root: &Path) -> Option<PathBuf> {
    let root = root.canonicalize().ok()?;
    let real = match file.canonicalize() {
        Ok(real) => real,
        Err(_) => {
            let name = match file.components().next_back() {
                Some(std::path::Component::Normal(name)) => name,
                _ => return None,
            };
            if file.symlink_metadata().is_ok() {
                return None;
            }
            file.parent()?.canonicalize().ok()?.join(name)
        }
    };
    (real.starts_with(&root) && real != root).then_some(real)
}

/// The path of a `file:` URI after its scheme (RFC 8089): `/p`, or
/// `//HOST/p` with no host or `localhost`; `None` for another host.
fn file_uri_path(rest: &str) -> Option<&str> {
    let Some(authority_and_path) = rest.strip_prefix("//") else {
        return Some(rest);
    };
    let (host, path) = match authority_and_path.find('/') {
        Some(i) => authority_and_path.split_at(i),
        None => (authority_and_path, ""),
    };
    (host.is_empty() || host.eq_ignore_ascii_case("localhost")).then_some(path)
}

/// Whether `s` is a URI scheme (RFC 3986: a letter, then letters, digits,
/// `+`, `-`, `.`), longer than one letter so that a Windows drive (`C:`)
/// stays a path.
fn is_uri_scheme(s: &str) -> bool {
    let mut chars = s.chars();
    s.len() > 1
        && chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
}
