//! Shared work: requests that ask at once for the same result (the same
//! frame's PNG, the same `/records` query) await one computation of it
//! rather than each running its own. A hundred followers woken by one new
//! frame encode it once; a dashboard reloaded in ten tabs reads the
//! records once.
//!
//! A computation runs in its own task: a client that goes away leaves it
//! to finish for the others (and for any cache it fills).

use std::collections::HashMap;
use std::future::Future;
use std::hash::Hash;
use std::sync::{Arc, Mutex};
use tokio::sync::watch;

/// The computations in progress, by key; each one's result, once there.
pub struct Flights<K, V> {
    running: Mutex<HashMap<K, watch::Receiver<Option<V>>>>,
}

impl<K, V> Default for Flights<K, V> {
    fn default() -> Self {
        Flights {
            running: Mutex::new(HashMap::new()),
        }
    }
}

/// A computation ended without a result (its task panicked or the
/// runtime is shutting down).
#[derive(Debug)]
pub struct Stopped;

impl<K, V> Flights<K, V>
where
    K: Hash + Eq + Clone + Send + Sync + 'static,
    V: Clone + Send + Sync + 'static,
{
    /// The value of `key`: what `cached` finds, else the result of the
    /// computation of `key` in progress, else of a new one, `work()`.
    ///
    /// `cached` is looked up under the flights' lock, and a computation
    /// leaves the flights only after `work` has ended, so a `work` that
    /// fills the cache `cached` reads before it ends leaves no gap in
    /// which a request finds neither and computes the value again.
    pub async fn get<Fut>(
        self: &Arc<Self>,
        key: K,
        cached: impl FnOnce() -> Option<V>,
        work: impl FnOnce() -> Fut,
    ) -> Result<V, Stopped>
    where
        Fut: Future<Output = V> + Send + 'static,
    {
        let mut flight = {
            let mut running = self.running.lock().expect("flights lock");
            if let Some(value) = cached() {
                return Ok(value);
            }
            match running.get(&key) {
                Some(flight) => flight.clone(),
                None => {
                    let (tx, rx) = watch::channel(None);
                    running.insert(key.clone(), rx.clone());
                    let landing = Landing {
                        flights: self.clone(),
                        key,
                    };
                    let work = work();
                    tokio::spawn(async move {
                        let _landing = landing;
                        tx.send_replace(Some(work.await));
                    });
                    rx
                }
            }
        };
        let done = flight
            .wait_for(Option::is_some)
            .await
            .map_err(|_| Stopped)?;
        Ok(done.clone().expect("waited for a result"))
    }

    /// Computations in progress.
    #[cfg(test)]
    pub fn in_progress(&self) -> usize {
        self.running.lock().expect("flights lock").len()
    }
}

/// Removes a computation from its [`Flights`] when its task ends, however
/// it ends (its waiters then see its sender dropped, if it sent nothing).
struct Landing<K: Hash + Eq, V> {
    flights: Arc<Flights<K, V>>,
    key: K,
}

impl<K: Hash + Eq, V> Drop for Landing<K, V> {
    fn drop(&mut self) {
        if let Ok(mut running) = self.flights.running.lock() {
            running.remove(&self.key);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures_util::future::{join, join_all};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use tokio::sync::Semaphore;

    /// A computation of `key` that counts its runs in `runs` and ends once
    /// `gate` has a permit.
    fn counted(
        key: u32,
        runs: &Arc<AtomicUsize>,
        gate: &Arc<Semaphore>,
    ) -> impl Future<Output = String> + Send + 'static {
        let (runs, gate) = (runs.clone(), gate.clone());
        async move {
            runs.fetch_add(1, Ordering::SeqCst);
            let _permit = gate.acquire().await.unwrap();
            format!("value {key}")
        }
    }

    /// Requests for one key made while its computation runs share it and
    /// its result; another key gets its own; once it has ended, a request
    /// computes again (nothing is cached here).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn requests_for_a_key_in_progress_share_its_computation() {
        let flights = Arc::new(Flights::<u32, String>::default());
        let runs = Arc::new(AtomicUsize::new(0));
        let gate = Arc::new(Semaphore::new(0));
        let (r, g) = (&runs, &gate);
        let ask = |key: u32| flights.get(key, || None, move || counted(key, r, g));
        // `join` polls the requests first (and `join_all` each of them
        // once, in order): all have joined a computation or started one
        // before the gate opens.
        let requests = join_all((0..16).map(|i| ask(if i < 15 { 7 } else { 8 })));
        let (answers, ()) = join(requests, async { gate.add_permits(1) }).await;
        let answers: Vec<String> = answers.into_iter().map(Result::unwrap).collect();
        assert_eq!(answers[..15], vec!["value 7".to_string(); 15][..]);
        assert_eq!(answers[15], "value 8");
        assert_eq!(
            runs.load(Ordering::SeqCst),
            2,
            "fifteen requests, one computation"
        );
        assert_eq!(flights.in_progress(), 0);
        assert_eq!(ask(7).await.unwrap(), "value 7");
        assert_eq!(runs.load(Ordering::SeqCst), 3);
    }

    /// A requester that goes away does not stop the computation: the
    /// others get its result; a cached value is returned without any.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_requester_gone_leaves_the_computation_to_the_others() {
        let flights = Arc::new(Flights::<u32, String>::default());
        let runs = Arc::new(AtomicUsize::new(0));
        let gate = Arc::new(Semaphore::new(0));
        let first = {
            let flights = flights.clone();
            let work = counted(1, &runs, &gate);
            tokio::spawn(async move { flights.get(1, || None, || work).await })
        };
        while flights.in_progress() == 0 {
            tokio::task::yield_now().await;
        }
        first.abort();
        assert!(first.await.unwrap_err().is_cancelled());
        let second = flights.get(1, || None, || async { unreachable!("joins the first") });
        let open = async {
            gate.add_permits(1);
        };
        let (second, ()) = join(second, open).await;
        assert_eq!(second.unwrap(), "value 1");
        assert_eq!(runs.load(Ordering::SeqCst), 1);
        let cached = flights
            .get(
                1,
                || Some("cached".to_string()),
                || async { unreachable!("cached") },
            )
            .await;
        assert_eq!(cached.unwrap(), "cached");
    }

    /// A computation that panics ends its waiters' wait with [`Stopped`]
    /// and leaves the flights.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_computation_that_panics_stops_its_waiters() {
        let flights = Arc::new(Flights::<u32, u32>::default());
        let got = flights
            .get(1, || None, || async { panic!("computation fails") })
            .await;
        assert!(got.is_err());
        assert_eq!(flights.in_progress(), 0);
    }
}
