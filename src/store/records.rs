//! A frame's records, read back from their block in the sample log, and
//! each record's incoming-radiance samples.

use super::samples::{self, decompress, SampleBlock};
use super::schema::{FrameRecordsValue, RecordBlock, RecordValue};
use super::{decode_value, keys, PackedSample, Store, StoreError, MAX_BLOCK_RECORDS};
use std::collections::BTreeMap;

impl Store {
    /// Where the records written in `frame` of `job` lie in the sample log
    /// (`None`: the frame wrote none, or is not stored).
    pub fn frame_records_value(
        &self,
        job: u64,
        frame: u32,
    ) -> Result<Option<FrameRecordsValue>, StoreError> {
        self.get("records", &keys::frame(job, frame))
    }

    /// Checks that `records` value `v` (under `key`) can describe a block
    /// in a log of `committed` bytes: rkyv accepts any bytes of the right
    /// length for a struct of integers, so a damaged value is caught here,
    /// as a corrupt `records` value, before anything is read or allocated
    /// for it.
    fn check_records_value(
        &self,
        key: &[u8],
        v: &FrameRecordsValue,
        committed: u64,
    ) -> Result<(), StoreError> {
        let end = v.offset.checked_add(u64::from(v.stored_len));
        let max_raw = (v.count as usize)
            .saturating_mul(std::mem::size_of::<rkyv::Archived<RecordValue>>())
            .saturating_add(256);
        let problem = if v.count == 0 || v.count > MAX_BLOCK_RECORDS {
            Some(format!(
                "{} records (1..={MAX_BLOCK_RECORDS} expected)",
                v.count
            ))
        } else if v.first_id > v.last_id || v.last_id - v.first_id < u64::from(v.count - 1) {
            Some(format!(
                "{} records cannot have ids {}..={}",
                v.count, v.first_id, v.last_id
            ))
        } else if v.raw_len as usize > max_raw {
            Some(format!(
                "{} bytes before zstd for {} records (at most {max_raw})",
                v.raw_len, v.count
            ))
        } else if v.offset < samples::MAGIC.len() as u64 || end.is_none_or(|e| e > committed) {
            Some(format!(
                "its block, {} bytes at offset {}, lies outside the sample log's committed {} bytes",
                v.stored_len,
                v.offset,
                committed
            ))
        } else {
            None
        };
        match problem {
            Some(problem) => Err(self.corrupt("records", key, problem)),
            None => Ok(()),
        }
    }

    /// The records of the block `v` (the `records` value under `key`),
    /// read from the log and checked against `v`.
    pub(super) fn record_block(
        &self,
        key: &[u8],
        v: &FrameRecordsValue,
    ) -> Result<Vec<RecordValue>, StoreError> {
        let in_log = |d: String| {
            self.log_error(format!(
                "records of {} at offset {}: {d}",
                keys::describe(key),
                v.offset
            ))
        };
        let log = self.lock_log();
        self.check_records_value(key, v, log.committed())?;
        let stored = log.read(v.offset, v.stored_len).map_err(in_log)?;
        drop(log);
        let raw = decompress(&stored, v.raw_len as usize).map_err(in_log)?;
        drop(stored);
        let block: RecordBlock = decode_value(&raw).map_err(in_log)?;
        let (job, frame) = keys::parse_frame(key).unwrap_or_default();
        if (block.job, block.frame) != (job, frame) {
            return Err(in_log(format!(
                "the block is job {} frame {}'s",
                block.job, block.frame
            )));
        }
        let ids_ok = block.records.windows(2).all(|w| w[0].id < w[1].id)
            && block.records.first().map_or(0, |r| r.id) == v.first_id
            && block.records.last().map_or(0, |r| r.id) == v.last_id;
        if block.records.len() != v.count as usize || !ids_ok {
            return Err(in_log(format!(
                "expected {} records, ids {}..={} increasing; found {}",
                v.count,
                v.first_id,
                v.last_id,
                block.records.len()
            )));
        }
        Ok(block.records)
    }

    /// Records written in `frame` of `job`, in id order.
    pub fn frame_records(&self, job: u64, frame: u32) -> Result<Vec<RecordValue>, StoreError> {
        let key = keys::frame(job, frame);
        match self.get::<FrameRecordsValue>("records", &key)? {
            Some(v) => self.record_block(&key, &v),
            None => Ok(Vec::new()),
        }
    }

    /// Every record version of `job` written in frames `0..=through`, in
    /// (frame, id) order, through `f` (streams: one frame's block at a time;
    /// the blocks of later frames are not read).
    pub fn for_each_record(
        &self,
        job: u64,
        through: u32,
        mut f: impl FnMut(u32, RecordValue),
    ) -> Result<(), StoreError> {
        self.for_each_record_block(job, 0..=through, |frame, block| {
            block.into_iter().for_each(|r| f(frame, r))
        })
    }

    /// The record blocks of `job` written in `frames`, in frame order, each
    /// with its frame through `f` (its records in id order; a frame that
    /// wrote none has no block): one block read at a time, and none
    /// outside `frames`.
    pub fn for_each_record_block(
        &self,
        job: u64,
        frames: std::ops::RangeInclusive<u32>,
        mut f: impl FnMut(u32, Vec<RecordValue>),
    ) -> Result<(), StoreError> {
        let (first, last) = frames.into_inner();
        if first > last {
            return Ok(());
        }
        for item in self
            .records
            .range(keys::frame(job, first)..=keys::frame(job, last))
        {
            let (k, v) = item.map_err(|e| StoreError::sled(&self.path, e))?;
            let (_, frame) = keys::parse_frame(&k)
                .ok_or_else(|| self.corrupt("records", &k, "malformed key"))?;
            let value: FrameRecordsValue = self.decode("records", &k, &v)?;
            f(frame, self.record_block(&k, &value)?);
        }
        Ok(())
    }

    /// The samples of record `id` written in `frame` of `job` (none if
    /// there is no such record), read from the sample log: the frame's
    /// record block, then the record's sample block.
    pub fn record_samples(
        &self,
        job: u64,
        frame: u32,
        id: u64,
    ) -> Result<Vec<PackedSample>, StoreError> {
        let key = keys::frame(job, frame);
        let Some(v) = self.get::<FrameRecordsValue>("records", &key)? else {
            return Ok(Vec::new());
        };
        self.check_records_value(&key, &v, self.sample_log_bytes())?;
        if !(v.first_id..=v.last_id).contains(&id) {
            return Ok(Vec::new());
        }
        let records = self.record_block(&key, &v)?;
        match records.binary_search_by_key(&id, |r| r.id) {
            Ok(i) => self.samples_of(&records[i], &keys::record(job, frame, id)),
            Err(_) => Ok(Vec::new()),
        }
    }

    /// The samples of every record written in `frame` of `job`, by id
    /// (a `tcg` job's resume: its state refers to them,
    /// `migrations/0010_tcg_state_refers_to_samples.md`).
    pub fn frame_record_samples(
        &self,
        job: u64,
        frame: u32,
    ) -> Result<BTreeMap<u64, Vec<PackedSample>>, StoreError> {
        (self.frame_records(job, frame)?.iter())
            .map(|r| Ok((r.id, self.samples_of_record(job, frame, r)?)))
            .collect()
    }

    /// The samples of record `r`, read from `frame`'s records of `job`
    /// ([`Self::frame_records`], [`Self::for_each_record`]): what
    /// [`Self::record_samples`] gives for its id, without reading the
    /// frame's record block again.
    pub fn samples_of_record(
        &self,
        job: u64,
        frame: u32,
        r: &RecordValue,
    ) -> Result<Vec<PackedSample>, StoreError> {
        self.samples_of(r, &keys::record(job, frame, r.id))
    }

    /// The samples of stored record `r` (`key` names it), read from the log.
    fn samples_of(&self, r: &RecordValue, key: &[u8]) -> Result<Vec<PackedSample>, StoreError> {
        if r.samples_count == 0 {
            return Ok(Vec::new());
        }
        let in_log = |d: String| {
            self.log_error(format!(
                "samples of {} at offset {}: {d}",
                keys::describe(key),
                r.samples_offset
            ))
        };
        let bytes = self
            .lock_log()
            .read(r.samples_offset, r.samples_len)
            .map_err(in_log)?;
        SampleBlock::unpack_bytes(&bytes, r.samples_count).map_err(in_log)
    }
}
