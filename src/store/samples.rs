//! A record's hemisphere samples in their stored form ([`SampleBlock`]),
//! and the append-only file that holds them beside the sled database
//! ([`SampleLog`], `samples.log`; schema 3, `migrations/0003_sample_log.md`),
//! with the frames' EXR files and (schema 4,
//! `migrations/0004_record_blocks.md`) each frame's records as one block:
//! every bulk value the store writes. sled 0.34's memory grows with what is
//! written to it, whatever its cache size (README, "Peak memory"); out here
//! they cost no memory.
//!
//! - A block is a record's `count` 8-byte [`PackedSample`]s in byte planes
//!   (byte 0 of every sample, then byte 1, …), zstd-compressed. Methods
//!   build it as soon as a record is gathered, so a frame never holds its
//!   samples at 32 bytes each for the store.
//! - The log is the file's 8-byte header [`MAGIC`] followed by blocks, back
//!   to back; a record says where its samples' block lies (offset, length,
//!   count), a frame's value in `frames` where its zstd-compressed EXR file
//!   lies, its value in `records` where its block of records lies. Nothing
//!   in the log is ever rewritten.
//! - `meta.samples_log_len` (u64 big-endian) is the log's committed length,
//!   written in each frame's sled transaction after the frame's EXR and
//!   blocks (samples, then records) were appended and synced. Bytes beyond it belong to a frame that was never
//!   acknowledged (a crash between the append and the transaction): the
//!   store's first append cuts them off, and says so; opening it leaves
//!   them (so that `inspect` of a store whose sled database lost commits,
//!   which looks the same, destroys nothing, and shows them). Where `meta`
//!   holds no committed length, the tail is what follows the header. A
//!   tail holding two or more frames' files is no crash's
//!   (`store::tail`): the store then refuses jobs and compaction (deleting a job still works). A log
//!   shorter than its committed length has lost acknowledged data: opening
//!   the store fails, naming the file.
//! - Schema 5 (`migrations/0005_log_generations.md`): `radcache compact`
//!   ([`super::compact`]) rewrites the log without its unreferenced bytes
//!   into a new file, so the log has a generation: `meta.samples_log_generation`
//!   (u64 big-endian; absent: 0) names the file, [`file_name`]. Any other
//!   log file in the directory is a compaction's leftover (the new file of
//!   one that never switched, or the old file of one that did) and is
//!   removed when the store is opened ([`remove_stale_logs`]).

use super::rgbe::PackedSample;
use crate::cache::gather::HemisphereSamples;
use crate::decimal::parse_canonical_u64;
use std::fs::{File, OpenOptions};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// The log's file name inside the store directory before any compaction
/// (generation 0; schemas 3 and 4 know only it).
pub const FILE_NAME: &str = "samples.log";

/// The file name of log generation `generation`: [`FILE_NAME`] for 0,
/// `samples.N.log` for the log the Nth compaction wrote.
pub fn file_name(generation: u64) -> String {
    match generation {
        0 => FILE_NAME.to_string(),
        n => format!("samples.{n}.log"),
    }
}

/// The generation of a log file name (the inverse of [`file_name`]), or
/// `None` if `name` names no log.
pub fn parse_file_name(name: &str) -> Option<u64> {
    if name == FILE_NAME {
        return Some(0);
    }
    let digits = name.strip_prefix("samples.")?.strip_suffix(".log")?;
    // Exactly what `file_name` writes: no `samples.0.log`, `samples.01.log`.
    parse_canonical_u64(digits).filter(|&n| n > 0)
}

/// Removes every log file in store directory `dir` but generation
/// `current`'s (a compaction's leftovers: see the module comment), then
/// syncs the directory; returns the files removed. Call only with the
/// store's lock held and its current log opened.
pub fn remove_stale_logs(dir: &Path, current: u64) -> Result<Vec<PathBuf>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("cannot list the directory: {e}"))?;
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if parse_file_name(&name).is_some_and(|g| g != current) {
            std::fs::remove_file(entry.path())
                .map_err(|e| format!("cannot remove leftover log {name}: {e}"))?;
            removed.push(entry.path());
        }
    }
    if !removed.is_empty() {
        sync_dir(dir)?;
    }
    Ok(removed)
}

/// Makes the directory's entries (a file created, renamed or removed)
/// durable.
pub fn sync_dir(dir: &Path) -> Result<(), String> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(|e| format!("cannot sync directory {}: {e}", dir.display()))
}

/// First 8 bytes of a sample log (format version 1).
pub const MAGIC: &[u8; 8] = b"RCSLOG1\n";

/// zstd level for sample blocks (STACK.md: level 3 ≈ 140 MB/s in).
const ZSTD_LEVEL: i32 = 3;

/// A record's samples in cell order, stored form: `count` 8-byte samples in
/// byte planes, zstd-compressed (empty when the record has none).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SampleBlock {
    pub count: u32,
    pub zstd: Vec<u8>,
}

impl SampleBlock {
    /// Packs gathered samples (age 0: all shot this frame).
    /// `dynamic[object]` tells whether an object is animated (the
    /// sample's hit-dynamic flag). The direction is not kept: it is the
    /// sample's strata cell (its index), jittered by the record's
    /// deterministic sample key.
    pub fn pack(samples: &HemisphereSamples, dynamic: &[bool]) -> Self {
        Self::from_packed(&pack_samples(samples, dynamic))
    }

    /// The block of samples already packed.
    pub fn from_packed(samples: &[PackedSample]) -> Self {
        if samples.is_empty() {
            return SampleBlock::default();
        }
        SampleBlock {
            count: samples.len() as u32,
            zstd: compress(&to_planar(samples)),
        }
    }

    /// The samples back, in cell order.
    pub fn unpack(&self) -> Result<Vec<PackedSample>, String> {
        Self::unpack_bytes(&self.zstd, self.count)
    }

    /// Unpacks `count` samples from a block's compressed bytes.
    pub fn unpack_bytes(zstd: &[u8], count: u32) -> Result<Vec<PackedSample>, String> {
        if count == 0 {
            return Ok(Vec::new());
        }
        let n = count as usize;
        let raw = decompress(zstd, n * PackedSample::BYTES)?;
        Ok(from_planar(&raw, n))
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Bytes of the samples before compression.
    pub fn raw_bytes(&self) -> u64 {
        u64::from(self.count) * PackedSample::BYTES as u64
    }
}

/// Gathered samples in their 8-byte form, in cell order, all of age 0
/// (shot this frame); `dynamic[object]` tells whether an object is
/// animated (the sample's hit-dynamic flag).
pub fn pack_samples(samples: &HemisphereSamples, dynamic: &[bool]) -> Vec<PackedSample> {
    (0..samples.radiance.len())
        .map(|i| {
            let object = samples.object.get(i).copied().unwrap_or(u32::MAX);
            let hit_dynamic =
                object != u32::MAX && dynamic.get(object as usize).copied().unwrap_or(false);
            PackedSample::pack(
                samples.radiance[i],
                samples.distance[i],
                object,
                hit_dynamic,
                0,
            )
        })
        .collect()
}

/// Byte planes of the 8-byte samples: byte 0 of every sample, then byte 1,
/// … (exponents, distance high bytes and flags then sit together, which
/// zstd compresses far better than interleaved samples).
pub(crate) fn to_planar(samples: &[PackedSample]) -> Vec<u8> {
    let n = samples.len();
    let mut out = vec![0u8; n * PackedSample::BYTES];
    for (i, s) in samples.iter().enumerate() {
        for (b, byte) in s.to_bytes().into_iter().enumerate() {
            out[b * n + i] = byte;
        }
    }
    out
}

fn from_planar(raw: &[u8], n: usize) -> Vec<PackedSample> {
    (0..n)
        .map(|i| PackedSample::from_bytes(std::array::from_fn(|b| raw[b * n + i])))
        .collect()
}

/// One zstd frame of `bytes`, stating its size and carrying the checksum
/// of its content: a damaged block is an error on reading, never other
/// bytes of the right length (blocks written before the checksum read as
/// they did).
///
/// Each thread keeps one compressor: a record's block is a few KB, and
/// making a zstd context for each (its tables allocated and freed again)
/// took 38 µs a 6 KB block against 22.5 µs reused, with the same bytes
/// out (a scratch benchmark of 20,000 blocks).
pub(crate) fn compress(bytes: &[u8]) -> Vec<u8> {
    thread_local! {
        static COMPRESSOR: std::cell::RefCell<zstd::bulk::Compressor<'static>> = {
            let mut compressor =
                zstd::bulk::Compressor::new(ZSTD_LEVEL).expect("zstd level 3 exists");
            compressor
                .set_parameter(zstd::zstd_safe::CParameter::ChecksumFlag(true))
                .expect("zstd takes the checksum flag");
            std::cell::RefCell::new(compressor)
        };
    }
    COMPRESSOR.with_borrow_mut(|compressor| {
        compressor
            .compress(bytes)
            .expect("zstd compression to memory cannot fail")
    })
}

/// Decompresses exactly `len` bytes.
pub(crate) fn decompress(bytes: &[u8], len: usize) -> Result<Vec<u8>, String> {
    // `len` comes from the store, and zstd reserves it before reading a
    // byte: a damaged length (a flipped high bit) would ask for terabytes
    // and abort the process. The frame states its own size ([`compress`]
    // writes whole frames), so the two must agree first.
    match zstd::zstd_safe::get_frame_content_size(bytes) {
        Ok(Some(n)) if n == len as u64 => {}
        Ok(Some(n)) => return Err(format!("zstd: expected {len} bytes, the frame holds {n}")),
        Ok(None) | Err(_) => {
            return Err(format!(
                "zstd: not a frame that states its size (expected {len} bytes)"
            ))
        }
    }
    let out = zstd::bulk::decompress(bytes, len).map_err(|e| format!("zstd: {e}"))?;
    if out.len() != len {
        return Err(format!(
            "zstd: expected {len} bytes, decompressed {}",
            out.len()
        ));
    }
    Ok(out)
}

/// The open sample log of a store (see the module comment). Appends go to
/// the end; [`SampleLog::commit`] makes them the committed length once the
/// sled transaction that references them is done, [`SampleLog::rollback`]
/// cuts them off when it failed.
pub struct SampleLog {
    path: PathBuf,
    file: File,
    /// Length the store's records may reference (`meta.samples_log_len`).
    committed: u64,
    /// Length including appends not committed yet.
    end: u64,
    /// Whether the file holds bytes past `committed` that no write of this
    /// process made: cut off by the first append.
    foreign_tail: bool,
    /// Whether that tail holds two or more frames' files, which no crash
    /// leaves ([`Self::look_for_lost_frames`]): then nothing is appended.
    lost_frames: bool,
}

/// Why a log that holds frames the database lost takes no append.
pub const LOST_FRAMES: &str = "past its committed length it holds the files of two or more \
     frames, which no crash leaves (at most one frame is appended before each commit): the \
     database lost commits; nothing was changed";

/// Makes `file`, a log in store directory `dir`, its header alone, durably.
fn write_header(file: &File, dir: &Path) -> Result<(), String> {
    file.set_len(0)
        .and_then(|()| file.write_all_at(MAGIC, 0))
        .and_then(|()| file.sync_all())
        .map_err(|e| e.to_string())?;
    // The file's name too: the first frame committed will reference it.
    sync_dir(dir)
}

/// Checks that `file` begins with a log's header.
fn check_header(file: &File) -> Result<(), String> {
    let mut head = [0u8; 8];
    file.read_exact_at(&mut head, 0)
        .map_err(|e| format!("cannot read its header: {e}"))?;
    if &head != MAGIC {
        return Err("not a radcache sample log (bad header)".into());
    }
    Ok(())
}

impl SampleLog {
    /// Opens (or creates) the log of generation `generation` ([`file_name`])
    /// in store directory `dir`, whose `meta` says `committed` bytes are
    /// referenced (`None`: nothing ever was: the file is created, or
    /// begun again where it holds no more than its header). A tail beyond
    /// `committed` (beyond the header for `None`) is kept until the first
    /// append ([`Self::append`]); a file shorter than `committed`, or
    /// without the header, is an error.
    pub fn open(dir: &Path, generation: u64, committed: Option<u64>) -> Result<SampleLog, String> {
        let path = dir.join(file_name(generation));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(committed.is_none())
            .truncate(false)
            .open(&path)
            .map_err(|e| match committed {
                Some(c) => format!(
                    "cannot open it ({e}), but the store references {c} bytes of it (lost?)"
                ),
                None => format!("cannot open it: {e}"),
            })?;
        let actual = file.metadata().map_err(|e| e.to_string())?.len();
        let header = MAGIC.len() as u64;
        // Nothing committed and no sample there (a new store, or one whose
        // creation was cut off): the file starts as its header.
        let fresh = committed.is_none() && actual <= header;
        let committed = match committed {
            // Nothing committed, yet samples there: a first frame's appends
            // that were never acknowledged, or a database sled recovered with
            // none of its commits (the rest of `meta` intact), which looks
            // the same. Kept past the header, as any tail below.
            None => header,
            // Appends at `c` would overwrite the header.
            Some(c) if c < header => {
                return Err(format!(
                    "the store references {c} bytes of it, less than its own header (damaged meta)"
                ));
            }
            Some(c) if actual < c => {
                return Err(format!(
                    "it is {actual} bytes, shorter than the {c} bytes the store's records reference (truncated or replaced?)"
                ));
            }
            Some(c) => c,
        };
        if fresh {
            write_header(&file, dir)?;
        } else {
            check_header(&file)?;
        }
        Ok(SampleLog {
            path,
            file,
            committed,
            end: committed,
            // The tail of a frame that was never acknowledged, or of frames
            // whose commits sled lost (a damaged database it recovered in
            // part): only a write cuts it, so that a store opened to be read
            // changes nothing.
            foreign_tail: !fresh && actual > committed,
            lost_frames: false,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The committed length.
    pub fn committed(&self) -> u64 {
        self.committed
    }

    /// The length including uncommitted appends.
    pub fn end(&self) -> u64 {
        self.end
    }

    /// Looks for frames the database lost in the tail past the committed
    /// length (`store::tail`: two EXR files or more, where a crash leaves
    /// one frame's appends at most) and, where it finds them, refuses every
    /// append from then on rather than cut them off. Returns whether it
    /// found them. The store calls it on open; a migration, whose batches
    /// append many frames' files before each commit, does not.
    pub fn look_for_lost_frames(&mut self) -> std::io::Result<bool> {
        if self.foreign_tail {
            let end = self.file.metadata()?.len();
            self.lost_frames = super::tail::exr_files(&self.file, self.committed, end, 2) >= 2;
        }
        Ok(self.lost_frames)
    }

    /// Whether [`Self::look_for_lost_frames`] found frames the database lost.
    pub fn holds_lost_frames(&self) -> bool {
        self.lost_frames
    }

    /// Appends `bytes` (not yet synced nor committed); returns their offset.
    pub fn append(&mut self, bytes: &[u8]) -> std::io::Result<u64> {
        if self.lost_frames {
            return Err(std::io::Error::other(LOST_FRAMES));
        }
        if self.foreign_tail {
            let tail = self.file.metadata()?.len().saturating_sub(self.end);
            self.file.set_len(self.end)?;
            self.foreign_tail = false;
            // Said, because it may be all a damaged database's frames.
            eprintln!(
                "warning: {}: cut off {tail} bytes past its committed length (a frame a crash \
                 cut off, or commits the database lost)",
                self.path.display()
            );
        }
        let offset = self.end;
        self.file.write_all_at(bytes, offset)?;
        self.end += bytes.len() as u64;
        Ok(offset)
    }

    /// Makes the appends durable (before the transaction that references
    /// them).
    pub fn sync(&self) -> std::io::Result<()> {
        self.file.sync_data()
    }

    /// The appends are referenced by a committed transaction.
    pub fn commit(&mut self) {
        self.committed = self.end;
    }

    /// Cuts off the uncommitted appends.
    pub fn rollback(&mut self) -> std::io::Result<()> {
        self.end = self.committed;
        self.file.set_len(self.committed)
    }

    /// The `len` bytes at `offset`, which must lie in the committed part.
    pub fn read(&self, offset: u64, len: u32) -> Result<Vec<u8>, String> {
        let stop = offset.saturating_add(u64::from(len));
        if offset < MAGIC.len() as u64 || stop > self.committed {
            return Err(format!(
                "bytes {offset}..{stop} lie outside its committed {} bytes",
                self.committed
            ));
        }
        let mut out = vec![0u8; len as usize];
        self.file
            .read_exact_at(&mut out, offset)
            .map_err(|e| format!("cannot read bytes {offset}..{stop}: {e}"))?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A damaged stored length is an error, not an allocation of that
    /// many bytes (2⁶⁰ aborted the process, or panicked with "capacity
    /// overflow"); the right one decompresses.
    #[test]
    fn a_stored_length_the_frame_does_not_hold_is_an_error() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i % 7) as u8).collect();
        let z = compress(&data);
        assert_eq!(decompress(&z, data.len()).unwrap(), data);
        for len in [999, 1001, 1 << 40, 1 << 60, usize::MAX] {
            let err = decompress(&z, len).unwrap_err();
            assert!(err.contains(&format!("expected {len} bytes")), "{err}");
        }
        let err = decompress(&[0x28, 0xb5, 0x2f], 10).unwrap_err();
        assert!(err.contains("not a frame"), "{err}");
    }

    /// A damaged block is an error, never other bytes of the right length
    /// (a wrong radiance, a broken EXR): each bit flipped in turn.
    #[test]
    fn a_damaged_block_never_decompresses_to_other_bytes() {
        let data: Vec<u8> = (0..2000u32).map(|i| (i * 7919 % 251) as u8).collect();
        let z = compress(&data);
        let mut wrong = 0;
        for i in 0..z.len() {
            for bit in 0..8 {
                let mut damaged = z.clone();
                damaged[i] ^= 1 << bit;
                if decompress(&damaged, data.len()).is_ok_and(|out| out != data) {
                    wrong += 1;
                }
            }
        }
        assert_eq!(wrong, 0, "{wrong} damaged blocks gave other bytes");
    }

    /// A committed length shorter than the header is refused: appends at
    /// it overwrote the header, and the store was unreadable from then on.
    #[test]
    fn a_committed_length_inside_the_header_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        drop(SampleLog::open(dir.path(), 0, None).unwrap());
        let err = SampleLog::open(dir.path(), 0, Some(3)).err().unwrap();
        assert!(err.contains("less than its own header"), "{err}");
        let log = SampleLog::open(dir.path(), 0, Some(MAGIC.len() as u64)).unwrap();
        assert_eq!(log.committed(), MAGIC.len() as u64);
    }

    #[test]
    fn log_file_names_round_trip_and_nothing_else_parses() {
        for g in [0, 1, 2, 10, u64::MAX] {
            assert_eq!(parse_file_name(&file_name(g)), Some(g));
        }
        assert_eq!(file_name(0), "samples.log");
        assert_eq!(file_name(3), "samples.3.log");
        for other in [
            "samples.0.log",
            "samples.03.log",
            "samples.x.log",
            "samples..log",
            "samples.log.bak",
            "samples.-1.log",
            "samples.+1.log",
            "db",
        ] {
            assert_eq!(parse_file_name(other), None, "{other}");
        }
    }
}
