//! The cache a stateful method (`trc`, `tcg`) carries to the next frame,
//! as of a job's last frame: its head and records, loaded on resume.

use super::schema::{StateHeadValue, StateRecordValue};
use super::{keys, Store, StoreError};

impl Store {
    /// The head of job `job`'s carried method state, if any.
    pub fn state_head(&self, job: u64) -> Result<Option<StateHeadValue>, StoreError> {
        self.get("state", &keys::state_head(job))
    }

    /// Job `job`'s carried method state (as of [`Self::state_head`]'s
    /// frame): the head's method-wide bytes and every state record, in id
    /// order.
    pub fn load_state(&self, job: u64) -> Result<Option<crate::method::MethodState>, StoreError> {
        let Some(head) = self.state_head(job)? else {
            return Ok(None);
        };
        let mut records = Vec::new();
        for item in self.state.scan_prefix(keys::job_prefix(job)) {
            let (k, v) = item.map_err(|e| StoreError::sled(&self.path, e))?;
            if k.len() == 8 {
                continue; // the head
            }
            let (_, id) = keys::parse_state_record(&k)
                .ok_or_else(|| self.corrupt("state", &k, "malformed key"))?;
            let value: StateRecordValue = self.decode("state", &k, &v)?;
            records.push((id, value.data));
        }
        Ok(Some(crate::method::MethodState {
            frame: head.frame,
            global: head.global,
            records,
            record_samples: Default::default(),
        }))
    }

    /// Forgets job `job`'s carried method state (a render that starts its
    /// chain over). The head goes first, so that a crash halfway leaves no
    /// head over partial records.
    pub fn clear_state(&self, job: u64) -> Result<(), StoreError> {
        self.state
            .remove(keys::state_head(job))
            .map_err(|e| StoreError::sled(&self.path, e))?;
        self.flush()?;
        self.remove_prefix(&self.state, &keys::job_prefix(job))?;
        self.flush()
    }

    /// The error for a state [`crate::method::Method::restore_state`]
    /// refused: a corrupt value in `state`, naming its key.
    pub fn state_error(&self, job: u64, e: crate::method::StateError) -> StoreError {
        let key = match e.record {
            Some(id) => keys::state_record(job, id).to_vec(),
            None => keys::state_head(job).to_vec(),
        };
        self.corrupt("state", &key, e.detail)
    }
}
