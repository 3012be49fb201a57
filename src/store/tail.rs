//! What lies in a sample log past its committed length ([`super::samples`]):
//! how many frames' appends.
//!
//! A frame's commit appends its EXR file first, then its blocks, and is
//! committed and flushed before the next frame appends anything (the log's
//! lock is held through all of it: `Store::commit_frame`). So a crash
//! leaves at most one frame's appends past the committed length. Two or
//! more EXR files there mean the database lost commits that no crash
//! explains: sled, meeting a damaged entry in its log, recovers the entries
//! before it and silently drops the rest (a `db` file with three bits
//! flipped, or cut short, opened as a store with its schema and no jobs).
//! Cutting that tail would throw away the only copy of those frames.
//!
//! The log is walked by its zstd frames' headers (RFC 8878 §3.1.1): every
//! block the store writes is one frame ([`super::samples::compress`]).
//! Only the first bytes of each frame are decompressed, to tell an EXR
//! file from a block of samples or records.

use std::fs::File;
use std::io::Read;
use std::os::unix::fs::FileExt;

/// The EXR files among the zstd frames of `file` from `start` to `end`,
/// counted up to `at_most`. A frame that does not parse (torn by a crash,
/// or not zstd) ends the walk.
pub(super) fn exr_files(file: &File, start: u64, end: u64, at_most: usize) -> usize {
    let mut count = 0;
    let mut at = start;
    while count < at_most {
        let Some(len) = frame_len(file, at, end) else {
            break;
        };
        if starts_exr(file, at, len) {
            count += 1;
        }
        at += len;
    }
    count
}

/// The zstd frame magic number, little-endian on disk.
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];

/// The length of the zstd frame at `at`, which must end by `end`.
fn frame_len(file: &File, at: u64, end: u64) -> Option<u64> {
    let read = |offset: u64, buf: &mut [u8]| {
        let fits = offset
            .checked_add(buf.len() as u64)
            .is_some_and(|e| e <= end);
        (fits && file.read_exact_at(buf, offset).is_ok()).then_some(())
    };
    let mut head = [0u8; 5];
    read(at, &mut head)?;
    if head[..4] != ZSTD_MAGIC {
        return None;
    }
    // Frame_Header_Descriptor: content size flag, single segment, checksum,
    // dictionary id flag; then the window descriptor (unless single
    // segment), the dictionary id and the content size.
    let descriptor = head[4];
    let single_segment = descriptor & 0x20 != 0;
    let checksum = descriptor & 0x04 != 0;
    let dictionary = [0, 1, 2, 4][usize::from(descriptor & 3)];
    let content_size = match descriptor >> 6 {
        0 => u64::from(single_segment),
        1 => 2,
        2 => 4,
        _ => 8,
    };
    let mut pos = at + 5 + u64::from(!single_segment) + dictionary + content_size;
    loop {
        // Block_Header: last block (bit 0), type (bits 1–2), size.
        let mut block = [0u8; 3];
        read(pos, &mut block)?;
        let header = u32::from_le_bytes([block[0], block[1], block[2], 0]);
        let size = u64::from(header >> 3);
        let content = match (header >> 1) & 3 {
            0 | 2 => size, // raw, compressed
            1 => 1,        // RLE: one byte, repeated
            _ => return None,
        };
        pos += 3 + content;
        if pos > end {
            return None;
        }
        if header & 1 != 0 {
            break;
        }
    }
    pos += if checksum { 4 } else { 0 };
    (pos <= end).then_some(pos - at)
}

/// Whether the zstd frame of `len` bytes at `at` decompresses to bytes
/// that begin as an EXR file does.
fn starts_exr(file: &File, at: u64, len: u64) -> bool {
    let frame = FileRange {
        file,
        at,
        end: at + len,
    };
    let mut magic = [0u8; 4];
    zstd::stream::read::Decoder::new(frame)
        .and_then(|mut d| d.read_exact(&mut magic))
        .is_ok_and(|()| magic == crate::film::EXR_MAGIC)
}

/// `file`'s bytes from `at` to `end`, read as a stream.
struct FileRange<'a> {
    file: &'a File,
    at: u64,
    end: u64,
}

impl Read for FileRange<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let want = (buf.len() as u64).min(self.end - self.at) as usize;
        let n = self.file.read_at(&mut buf[..want], self.at)?;
        self.at += n as u64;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::samples::compress;
    use std::io::Write;

    /// A log's worth of blocks: EXR files and other blocks, large ones
    /// (several zstd blocks, some stored raw) and tiny ones.
    fn blocks() -> Vec<(Vec<u8>, bool)> {
        let mut noise = crate::sampling::Rng::new(crate::sampling::SampleKey {
            seed: 1,
            frame: None,
            item: 0,
            sample: 0,
        });
        let mut exr = crate::film::EXR_MAGIC.to_vec();
        exr.extend((0..400_000).map(|_| (noise.next_f32() * 256.0) as u8));
        let mut small_exr = crate::film::EXR_MAGIC.to_vec();
        small_exr.extend([0u8; 10]);
        vec![
            (vec![7u8; 3], false),
            (exr.clone(), true),
            ((0..300_000u32).map(|i| (i % 251) as u8).collect(), false),
            (small_exr, true),
            (vec![0u8; 1_000_000], false),
            (exr, true),
        ]
    }

    #[test]
    fn the_exr_files_among_a_logs_blocks_are_counted() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log");
        let mut f = File::create(&path).unwrap();
        f.write_all(b"HEADER!\n").unwrap();
        let mut ends = Vec::new();
        let mut exrs_before = vec![0];
        for (bytes, exr) in blocks() {
            f.write_all(&compress(&bytes)).unwrap();
            ends.push(f.metadata().unwrap().len());
            exrs_before.push(exrs_before.last().unwrap() + usize::from(exr));
        }
        let file = File::open(&path).unwrap();
        let end = *ends.last().unwrap();
        assert_eq!(exr_files(&file, 8, end, usize::MAX), 3);
        assert_eq!(exr_files(&file, 8, end, 2), 2);
        // From each block's end: the EXR files after it.
        for (i, &at) in ends.iter().enumerate() {
            let after = exrs_before.last().unwrap() - exrs_before[i + 1];
            assert_eq!(
                exr_files(&file, at, end, usize::MAX),
                after,
                "after block {i}"
            );
        }
        // A torn last block ends the walk before it; garbage ends it too.
        let torn = end - 10;
        assert_eq!(exr_files(&file, 8, torn, usize::MAX), 2);
        assert_eq!(exr_files(&file, 9, end, usize::MAX), 0);
    }
}
