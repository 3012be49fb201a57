//! The records alive at a frame of a job (`/records`), kept between
//! queries.
//!
//! A frame's record block holds the record versions that frame wrote
//! (`store::keys`), and a record at frame N is its latest version written
//! at or before N: the records alive at N fold in every block of frames
//! 0..=N. On a 400-frame `tcg` job at 64×64 (544 records, every one
//! written again each frame), a query at frame 399 took 70–100 ms against
//! 2–3 ms at frame 5, growing with the job (and with its records: more
//! pixels, more of them). So the sets a query passes are kept, one every
//! [`CHECKPOINT_FRAMES`] frames and one at the query's own frame, and a
//! query starts from the nearest kept set at or before its frame: once a
//! query has read a job's blocks up to a frame, a query at any frame up to
//! there reads fewer than [`CHECKPOINT_FRAMES`] blocks (4–6 ms at frame
//! 398 of that job), and a client following the job one frame at a time
//! reads one. The query that keeps the sets costs more than one that
//! kept nothing would (100 ms there; twice as long on a `trc` job's,
//! whose sets hold every version that lives past its block, where a
//! single query could drop those dead at its frame).
//!
//! Why sets kept rather than blocks skipped: to skip the blocks that hold
//! no record alive at N, the store would have to keep each block's latest
//! `last_frame`, and it does not (that is a schema change); a `trc` record
//! lives at most `max_life` frames, but `tcg`'s may live for ever, so no
//! bound from the method serves every method. Sharing identical
//! concurrent queries would leave each one as slow as before.
//!
//! A kept set stays right while the blocks it folded in stay as they are.
//! While the server runs, it holds the store (a store serves one process),
//! and only its worker writes a job's frames: it tells
//! [`AliveSets::written`] of every frame it writes, which drops the job's
//! sets at or after that frame, and a query that was reading meanwhile
//! keeps none of its sets.

use crate::store::schema::RecordValue;
use crate::store::StoreError;
use std::collections::{BTreeMap, HashMap};
use std::ops::RangeInclusive;
use std::sync::{Arc, Mutex};

/// Frames between two kept sets of a job: a query reads fewer blocks than
/// this past the nearest kept set.
pub const CHECKPOINT_FRAMES: u32 = 16;

/// Most bytes (estimated: [`Alive::bytes`]) of sets kept in all, the
/// oldest kept going first past it; as much as the PNG cache holds.
const KEPT_BYTES: usize = 64 * 1024 * 1024;

/// A record version in a set, with the frame that wrote it.
pub type Version = (u32, RecordValue);

/// A job's records as of a frame: each record's latest version written at
/// or before it, where that version lives to the frame or later. The
/// records alive at the frame are those among them created by then
/// ([`Alive::alive`]); a record left out is alive at no later frame
/// unless a later block writes it again, so that a later frame's set
/// follows from this one and the blocks after it.
#[derive(Clone, Debug, Default)]
pub struct Alive {
    /// The first frame whose block is not folded in: the set is as of the
    /// frame before (0: no block read yet). One past a `u32` frame.
    next: u64,
    records: BTreeMap<u64, Version>,
}

impl Alive {
    /// The frame the set is as of (`None`: before frame 0).
    fn frame(&self) -> Option<u32> {
        self.next.checked_sub(1).map(|f| f as u32)
    }

    /// The records alive at the set's frame, in id order.
    pub fn alive(&self) -> impl Iterator<Item = &Version> {
        let frame = self.frame().unwrap_or(0);
        self.records
            .values()
            .filter(move |(_, r)| r.created_frame <= frame)
    }

    /// Folds in the record versions frame `frame` wrote (one a record; at
    /// or after the set's `next`).
    fn take(&mut self, frame: u32, block: Vec<RecordValue>) {
        for r in block {
            if r.last_frame >= frame {
                self.records.insert(r.id, (frame, r));
            } else {
                self.records.remove(&r.id);
            }
        }
        self.age_to(frame);
    }

    /// The set as of `frame` (at or after its `next`), no block written in
    /// between: the records whose versions died before it go. Done after
    /// every block, so that a set holds the records alive at its frame
    /// (and those created later that a block wrote early), not every
    /// record the job wrote.
    fn age_to(&mut self, frame: u32) {
        self.records.retain(|_, (_, r)| r.last_frame >= frame);
        self.next = u64::from(frame) + 1;
    }

    /// Ages the set through each checkpoint frame before `frame`, handing
    /// `keep` a copy at each.
    fn pass_checkpoints(&mut self, frame: u32, keep: &mut dyn FnMut(Arc<Alive>)) {
        loop {
            let checkpoint =
                self.next.div_ceil(u64::from(CHECKPOINT_FRAMES)) * u64::from(CHECKPOINT_FRAMES);
            if checkpoint >= u64::from(frame) {
                return;
            }
            self.age_to(checkpoint as u32);
            keep(Arc::new(self.clone()));
        }
    }

    /// Estimated bytes: the records with the map's own nodes (about half
    /// as much again), and a little for the set itself.
    fn bytes(&self) -> usize {
        64 + self.records.len() * std::mem::size_of::<(u64, Version)>() * 3 / 2
    }
}

/// A job's record blocks of the frames in a range, read in frame order
/// through a callback (`Store::for_each_record_block`; tests count them).
pub type Blocks<'a> = dyn FnMut(RangeInclusive<u32>, &mut dyn FnMut(u32, Vec<RecordValue>)) -> Result<(), StoreError>
    + 'a;

/// `alive` brought forward to frame `to` (at or after its own) by the
/// blocks of the frames between, read by `read`; `keep` gets the sets at
/// the checkpoint frames passed before `to`.
fn walk(
    mut alive: Alive,
    to: u32,
    read: &mut Blocks,
    keep: &mut dyn FnMut(Arc<Alive>),
) -> Result<Alive, StoreError> {
    if alive.next > u64::from(to) {
        return Ok(alive);
    }
    read(alive.next as u32..=to, &mut |frame, block| {
        alive.pass_checkpoints(frame, keep);
        alive.take(frame, block);
        if frame % CHECKPOINT_FRAMES == 0 && frame < to {
            keep(Arc::new(alive.clone()));
        }
    })?;
    alive.pass_checkpoints(to, keep);
    alive.age_to(to);
    Ok(alive)
}

/// The records of store job `sid` as of frame `frame`, from the nearest
/// set `kept` at or before it and the blocks after, read by `read`; the
/// sets it passes, and its own, are kept.
pub fn alive_at(
    kept: &Mutex<AliveSets>,
    sid: u64,
    frame: u32,
    read: &mut Blocks,
) -> Result<Arc<Alive>, StoreError> {
    let lock = || kept.lock().expect("alive sets lock");
    let (start, generation) = lock().begin(sid, frame);
    if start.frame() == Some(frame) {
        return Ok(start);
    }
    let mut keep = |set: Arc<Alive>| lock().keep(sid, generation, set);
    let alive = Arc::new(walk(Alive::clone(&start), frame, read, &mut keep)?);
    keep(alive.clone());
    Ok(alive)
}

/// The sets kept of every job, by store job id.
pub struct AliveSets {
    /// Most bytes kept ([`KEPT_BYTES`]; tests set less).
    limit: usize,
    jobs: HashMap<u64, JobSets>,
    /// Every kept set, as (job, frame), by when it was kept: the oldest go
    /// first past `limit`.
    by_age: BTreeMap<u64, (u64, u32)>,
    stamps: u64,
    bytes: usize,
}

/// One job's kept sets and what tells whether a query may keep its own.
#[derive(Default)]
struct JobSets {
    /// By the frame each is as of, with its stamp in `by_age`.
    sets: BTreeMap<u32, (u64, Arc<Alive>)>,
    /// Bumped when a frame that a query may have read is written again: a
    /// query begun before keeps none of its sets (it may have read the
    /// frame's block as it was).
    generation: u64,
    /// The latest frame a query has begun to read to: a frame written
    /// after it is in no kept set, nor in any set being made.
    asked: Option<u32>,
    /// The frame of the set kept at a query's own frame, off the
    /// checkpoints: the next such set replaces it (one a job is enough for
    /// a client that follows the job or steps through it).
    own: Option<u32>,
}

impl Default for AliveSets {
    fn default() -> Self {
        AliveSets::with_limit(KEPT_BYTES)
    }
}

impl AliveSets {
    fn with_limit(limit: usize) -> Self {
        AliveSets {
            limit,
            jobs: HashMap::new(),
            by_age: BTreeMap::new(),
            stamps: 0,
            bytes: 0,
        }
    }

    /// The kept set of job `sid` nearest at or before `frame` (an empty
    /// one, before frame 0, if none) and the generation that the query,
    /// which reads the job's blocks up to `frame`, keeps its sets in.
    fn begin(&mut self, sid: u64, frame: u32) -> (Arc<Alive>, u64) {
        let job = self.jobs.entry(sid).or_default();
        job.asked = job.asked.max(Some(frame));
        let start = job
            .sets
            .range(..=frame)
            .next_back()
            .map(|(_, (_, set))| set.clone())
            .unwrap_or_default();
        (start, job.generation)
    }

    /// Keeps `set` of job `sid`, made by a query begun in `generation`,
    /// unless a frame it may have read was written since or the job is
    /// deleted.
    fn keep(&mut self, sid: u64, generation: u64, set: Arc<Alive>) {
        let Some(job) = self.jobs.get(&sid).filter(|j| j.generation == generation) else {
            return;
        };
        let own = job.own;
        let Some(frame) = set.frame() else { return };
        let checkpoint = frame % CHECKPOINT_FRAMES == 0;
        if let Some(own) = own.filter(|_| !checkpoint) {
            self.drop_set(sid, own);
        }
        self.drop_set(sid, frame);
        let stamp = self.stamps;
        self.stamps += 1;
        self.bytes += set.bytes();
        self.by_age.insert(stamp, (sid, frame));
        let job = self.jobs.get_mut(&sid).expect("found above");
        job.sets.insert(frame, (stamp, set));
        if !checkpoint {
            job.own = Some(frame);
        }
        while self.bytes > self.limit {
            let Some((_, (sid, frame))) = self.by_age.pop_first() else {
                break;
            };
            self.drop_set(sid, frame);
        }
    }

    /// Drops job `sid`'s set at `frame`, if kept.
    fn drop_set(&mut self, sid: u64, frame: u32) {
        let Some(job) = self.jobs.get_mut(&sid) else {
            return;
        };
        if let Some((stamp, set)) = job.sets.remove(&frame) {
            self.by_age.remove(&stamp);
            self.bytes -= set.bytes();
        }
        if job.own == Some(frame) {
            job.own = None;
        }
    }

    /// Frame `frame` of job `sid` is written (again): the sets that
    /// folded in its block as it was go, and so do those of queries
    /// reading now.
    pub fn written(&mut self, sid: u64, frame: u32) {
        let Some(job) = self.jobs.get_mut(&sid) else {
            return;
        };
        // A new frame past every frame asked (a job rendered in order):
        // no set has read it, none goes.
        if job.asked.is_none_or(|asked| asked < frame) {
            return;
        }
        job.generation += 1;
        let stale: Vec<u32> = job.sets.range(frame..).map(|(&f, _)| f).collect();
        for f in stale {
            self.drop_set(sid, f);
        }
    }

    /// Job `sid` is deleted: its sets go, and its queries keep none.
    pub fn forget(&mut self, sid: u64) {
        let Some(job) = self.jobs.get(&sid) else {
            return;
        };
        let frames: Vec<u32> = job.sets.keys().copied().collect();
        for f in frames {
            self.drop_set(sid, f);
        }
        self.jobs.remove(&sid);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::cell::Cell;

    /// A job's blocks by frame, each in id order.
    type History = BTreeMap<u32, Vec<RecordValue>>;

    /// A record version with nothing but its id and life (the worker's
    /// tests take it too).
    pub(crate) fn version(id: u64, created: u32, last_frame: u32) -> RecordValue {
        RecordValue {
            id,
            created_frame: created,
            last_frame,
            position: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            irradiance: [0.0; 3],
            grad_translation: [[0.0; 3]; 3],
            grad_rotation: [[0.0; 3]; 3],
            radius: 1.0,
            object: 0,
            strata_theta: 0,
            strata_phi: 0,
            samples_count: 0,
            samples_offset: 0,
            samples_len: 0,
        }
    }

    /// What `/records` defines: each record's latest version written at
    /// or before `frame`, if it is alive there, in id order.
    fn by_definition(history: &History, frame: u32) -> Vec<Version> {
        let mut latest = BTreeMap::new();
        for (&written, block) in history.range(..=frame) {
            for r in block {
                latest.insert(r.id, (written, r.clone()));
            }
        }
        latest
            .into_values()
            .filter(|(_, r)| r.created_frame <= frame && frame <= r.last_frame)
            .collect()
    }

    /// The records alive at `frame` by [`alive_at`] over `history`,
    /// counting the blocks read in `blocks`.
    fn query(
        kept: &Mutex<AliveSets>,
        history: &History,
        frame: u32,
        blocks: &Cell<usize>,
    ) -> Vec<Version> {
        let mut read = |frames: RangeInclusive<u32>, f: &mut dyn FnMut(u32, Vec<RecordValue>)| {
            for (&written, block) in history.range(frames) {
                blocks.set(blocks.get() + 1);
                f(written, block.clone());
            }
            Ok(())
        };
        let alive = alive_at(kept, 1, frame, &mut read).unwrap();
        alive.alive().cloned().collect()
    }

    /// xorshift64: the same histories on every run.
    struct Rng(u64);

    impl Rng {
        fn below(&mut self, n: u32) -> u32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 % u64::from(n)) as u32
        }
    }

    /// The block of frame `frame`: new records living one frame (`ic`) or
    /// a few (`trc`), records of `pool` written again living on (some for
    /// ever, as `tcg`'s) or cut short (a version dead when written), or
    /// none at all (a frame that wrote none).
    fn block(rng: &mut Rng, frame: u32, pool: &mut Vec<(u64, u32)>) -> Vec<RecordValue> {
        let mut block = BTreeMap::new();
        if rng.below(8) == 0 {
            return Vec::new();
        }
        for _ in 0..rng.below(6) {
            let id = 1000 * u64::from(frame) + block.len() as u64;
            let life = [1, 1, 3, 8][rng.below(4) as usize];
            block.insert(id, version(id, frame, frame + life - 1));
            pool.push((id, frame));
        }
        for _ in 0..rng.below(6) {
            let Some(&(id, created)) = pool.get(rng.below(pool.len().max(1) as u32) as usize)
            else {
                break;
            };
            let last = match rng.below(5) {
                0 => u32::MAX,
                1 => frame.saturating_sub(1).max(created),
                n => frame + n,
            };
            block.entry(id).or_insert(version(id, created, last));
        }
        block.into_values().collect()
    }

    fn history(rng: &mut Rng, frames: u32) -> History {
        let mut pool = Vec::new();
        (0..frames)
            .map(|f| (f, block(rng, f, &mut pool)))
            .filter(|(_, b)| !b.is_empty())
            .collect()
    }

    /// Queries in any order, from kept sets or not, give what the
    /// definition gives: over histories of every method's kind of records,
    /// with frames written again (the worker telling of it) between
    /// queries, and with room for few kept sets as for many.
    #[test]
    fn kept_sets_give_the_records_alive_by_definition() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for limit in [KEPT_BYTES, 4096] {
            for _ in 0..4 {
                let frames = 120;
                let mut history = history(&mut rng, frames);
                let kept = Mutex::new(AliveSets::with_limit(limit));
                let blocks = Cell::new(0);
                for _ in 0..200 {
                    if rng.below(10) == 0 {
                        // A frame written again, as a resumed chain does.
                        let f = rng.below(frames);
                        history.insert(f, block(&mut rng, f, &mut vec![(3, 0), (1001, 1)]));
                        kept.lock().unwrap().written(1, f);
                    }
                    let frame = rng.below(frames + 10);
                    let got = query(&kept, &history, frame, &blocks);
                    assert_eq!(got, by_definition(&history, frame), "frame {frame}");
                    assert!(kept.lock().unwrap().bytes <= limit);
                }
            }
        }
    }

    /// Once a query has read a job's blocks, a query at any frame up to
    /// there reads fewer than a checkpoint's frames of them, a client
    /// following the job frame by frame reads one a frame, and the answers
    /// are still the definition's.
    #[test]
    fn a_query_reads_the_blocks_after_the_nearest_kept_set_only() {
        let mut rng = Rng(7);
        let mut pool = Vec::new();
        // Every frame writes a block, and a record that lives for ever, as
        // `tcg`'s do (ids above the others': the block stays in id order).
        let history: History = (0..420)
            .map(|f| {
                let mut b = block(&mut rng, f, &mut pool);
                b.push(version(u64::MAX - u64::from(f), f, u32::MAX));
                (f, b)
            })
            .collect();
        let kept = Mutex::new(AliveSets::default());
        let blocks = Cell::new(0);
        let read = |frame| {
            blocks.set(0);
            let got = query(&kept, &history, frame, &blocks);
            assert_eq!(got, by_definition(&history, frame), "frame {frame}");
            blocks.get()
        };
        assert_eq!(read(399), 400, "the first query reads every block");
        for frame in [398, 5, 200, 300, 17, 16, 0, 383, 399] {
            let n = read(frame);
            assert!(
                n < CHECKPOINT_FRAMES as usize,
                "{n} blocks read for frame {frame}"
            );
        }
        for frame in 400..420 {
            assert_eq!(read(frame), 1, "following, frame {frame}");
        }
    }

    /// A query that was reading when a frame it read was written again
    /// keeps none of its sets (it read the block as it was): the next
    /// query reads the new block.
    #[test]
    fn a_query_overtaken_by_a_write_keeps_nothing() {
        let kept = Mutex::new(AliveSets::default());
        let old: History = (0..40).map(|f| (f, vec![version(1, 0, f)])).collect();
        let mut new = old.clone();
        new.insert(2, vec![version(1, 0, 2), version(2, 2, u32::MAX)]);
        let mut read = |frames: RangeInclusive<u32>, f: &mut dyn FnMut(u32, Vec<RecordValue>)| {
            for (&written, block) in old.range(frames) {
                if written == 3 {
                    // The worker writes frame 2 again and says so.
                    kept.lock().unwrap().written(1, 2);
                }
                f(written, block.clone());
            }
            Ok(())
        };
        let alive = alive_at(&kept, 1, 39, &mut read).unwrap();
        assert_eq!(alive.alive().count(), 1, "read as the blocks were");
        let got = query(&kept, &new, 39, &Cell::new(0));
        assert_eq!(got, by_definition(&new, 39));
        assert_eq!(got.len(), 2);
    }

    /// A set holds the records alive at its frame, not every record the
    /// job wrote before: over 1000 frames of 100 new records living 3
    /// frames each, and one record written again every frame, at most the
    /// 301 alive at once; a record whose later version is dead is dropped,
    /// and a still later live version takes it again.
    #[test]
    fn a_set_holds_the_records_alive_at_its_frame_only() {
        let mut alive = Alive::default();
        let mut most = 0;
        let mut next_id = 1;
        for written in 0..1000 {
            // Record 0, written again each frame, alive in that frame only.
            let mut block = vec![version(0, written, written)];
            for _ in 0..100 {
                block.push(version(next_id, written, written + 2));
                next_id += 1;
            }
            alive.take(written, block);
            most = most.max(alive.records.len());
        }
        assert_eq!(alive.alive().count(), 301);
        assert!(alive.alive().all(|(w, r)| r.last_frame >= 999 && *w >= 997));
        assert_eq!(alive.records[&0].0, 999);
        assert!(most <= 301, "{most} records held at once");
        let mut alive = Alive::default();
        alive.take(0, vec![version(7, 0, 20)]);
        alive.take(5, vec![version(7, 0, 4)]);
        assert!(alive.records.is_empty());
        alive.take(9, vec![version(7, 9, 12)]);
        assert_eq!(alive.records[&7].0, 9);
    }
}
