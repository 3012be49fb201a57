//! Shared work: requests that ask at once for the same result (the same
//! frame's PNG, the same `/records` query) await one computation of it
//! rather than each running its own. A hundred followers woken by one new
//! frame encode it once; a dashboard reloaded in ten tabs reads the
//! records once.
//!
//! A computation runs in its own task: a client that goes away leaves it
//! to finish for the others (and for any cache it fills). Work that waits
//! for a slot first asks, once it has one, whether anyone still awaits it
//! ([`Wanted::still`]): requests made and dropped at once (their clients
//! gone) leave nothing to do.

use std::collections::HashMap;
use std::future::Future;
use std::hash::Hash;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use tokio::sync::watch;

/// A computation's channel: its result, once there, to every requester
/// subscribed.
type Channel<V> = Arc<watch::Sender<Option<V>>>;

/// The computations in progress, by key.
pub struct Flights<K, V> {
    running: Mutex<HashMap<K, Channel<V>>>,
}

impl<K, V> Default for Flights<K, V> {
    fn default() -> Self {
        Flights {
            running: Mutex::new(HashMap::new()),
        }
    }
}

/// A computation ended without a result (its task panicked, or the
/// runtime is shutting down).
#[derive(Debug)]
pub struct Stopped;

impl<K, V> Flights<K, V>
where
    K: Hash + Eq + Clone + Send + Sync + 'static,
    V: Clone + Send + Sync + 'static,
{
    /// The value of `key`: what `cached` finds, else the result of the
    /// computation of `key` in progress, else of a new one, `work(wanted)`
    /// (`wanted` says whether anyone still awaits it).
    ///
    /// `cached` is looked up under the flights' lock, and a computation
    /// leaves the flights, under that lock, only after `work` has ended,
    /// so a `work` that fills the cache `cached` reads leaves no gap in
    /// which a request finds neither and computes the value again.
    pub async fn get<Fut>(
        self: &Arc<Self>,
        key: K,
        cached: impl FnOnce() -> Option<V>,
        work: impl FnOnce(Wanted<K, V>) -> Fut,
    ) -> Result<V, Stopped>
    where
        Fut: Future<Output = V> + Send + 'static,
    {
        let (mut result, started) = {
            let mut running = self.lock();
            if let Some(value) = cached() {
                return Ok(value);
            }
            match running.get(&key) {
                Some(channel) => (channel.subscribe(), None),
                None => {
                    let channel: Channel<V> = Arc::new(watch::channel(None).0);
                    running.insert(key.clone(), channel.clone());
                    (channel.subscribe(), Some(channel))
                }
            }
        };
        // Spawned outside the lock: a runtime shutting down drops the task
        // at once, and its landing takes the lock.
        if let Some(channel) = started {
            let wanted = Wanted {
                flights: self.clone(),
                key,
                channel,
            };
            let landing = Landing(Some(wanted.clone()));
            let work = work(wanted);
            tokio::spawn(async move { landing.land(work.await) });
        }
        let done = result
            .wait_for(Option::is_some)
            .await
            .map_err(|_| Stopped)?;
        Ok(done.clone().expect("waited for a result"))
    }

    /// The map holds no invariant a panic could break: a poisoned lock is
    /// taken as it is.
    fn lock(&self) -> MutexGuard<'_, HashMap<K, Channel<V>>> {
        self.running.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Computations in progress.
    #[cfg(test)]
    pub fn in_progress(&self) -> usize {
        self.lock().len()
    }
}

/// A computation's place in its [`Flights`], given to its work.
pub struct Wanted<K, V> {
    flights: Arc<Flights<K, V>>,
    key: K,
    channel: Channel<V>,
}

impl<K: Clone, V> Clone for Wanted<K, V> {
    fn clone(&self) -> Self {
        Wanted {
            flights: self.flights.clone(),
            key: self.key.clone(),
            channel: self.channel.clone(),
        }
    }
}

impl<K, V> Wanted<K, V>
where
    K: Hash + Eq + Clone + Send + Sync + 'static,
    V: Clone + Send + Sync + 'static,
{
    /// Whether a requester still awaits the computation; if none does, it
    /// leaves the flights (under their lock, so that no one can join it
    /// after this answer), and a request for its key from now on starts
    /// a new one. Its work may then stop: its result reaches no one.
    pub fn still(&self) -> bool {
        let mut running = self.flights.lock();
        if self.channel.receiver_count() > 0 {
            return true;
        }
        self.leave(&mut running);
        false
    }

    /// Removes the computation from `running`, if it is still there (not
    /// another one of the same key, started after it left).
    fn leave(&self, running: &mut HashMap<K, Channel<V>>) {
        if running
            .get(&self.key)
            .is_some_and(|c| Arc::ptr_eq(c, &self.channel))
        {
            running.remove(&self.key);
        }
    }
}

/// Ends a computation: [`Landing::land`] leaves the flights and sends the
/// result, under the flights' lock; dropped without it (the work panicked,
/// or its task was dropped) it leaves them, and its requesters see the
/// channel closed.
struct Landing<K, V>(Option<Wanted<K, V>>)
where
    K: Hash + Eq + Clone + Send + Sync + 'static,
    V: Clone + Send + Sync + 'static;

impl<K, V> Landing<K, V>
where
    K: Hash + Eq + Clone + Send + Sync + 'static,
    V: Clone + Send + Sync + 'static,
{
    fn land(mut self, value: V) {
        if let Some(wanted) = self.0.take() {
            let mut running = wanted.flights.lock();
            wanted.leave(&mut running);
            wanted.channel.send_replace(Some(value));
        }
    }
}

impl<K, V> Drop for Landing<K, V>
where
    K: Hash + Eq + Clone + Send + Sync + 'static,
    V: Clone + Send + Sync + 'static,
{
    fn drop(&mut self) {
        if let Some(wanted) = self.0.take() {
            wanted.leave(&mut wanted.flights.lock());
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
        let ask = |key: u32| flights.get(key, || None, move |_| counted(key, r, g));
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
            tokio::spawn(async move { flights.get(1, || None, |_| work).await })
        };
        while flights.in_progress() == 0 {
            tokio::task::yield_now().await;
        }
        first.abort();
        assert!(first.await.unwrap_err().is_cancelled());
        let second = flights.get(1, || None, |_| async { unreachable!("joins the first") });
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
                |_| async { unreachable!("cached") },
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
            .get(1, || None, |_| async { panic!("computation fails") })
            .await;
        assert!(got.is_err());
        assert_eq!(flights.in_progress(), 0);
    }

    /// Work whose requesters have all gone finds no one wants it, and
    /// leaves the flights at that moment: the next request for its key
    /// starts a new computation rather than joining one whose result
    /// is to be dropped. While one waits, it is wanted.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn work_whose_requesters_are_gone_is_no_longer_wanted() {
        let flights = Arc::new(Flights::<u32, bool>::default());
        let gate = Arc::new(Semaphore::new(0));
        let g = gate.clone();
        // What the first work found: 0 not yet asked, 1 wanted, 2 not.
        let found = Arc::new(AtomicUsize::new(0));
        let f = found.clone();
        let first = {
            let flights = flights.clone();
            tokio::spawn(async move {
                let work = |wanted: Wanted<u32, bool>| async move {
                    let _permit = g.acquire().await.unwrap();
                    let still = wanted.still();
                    f.store(if still { 1 } else { 2 }, Ordering::SeqCst);
                    still
                };
                flights.get(1, || None, work).await
            })
        };
        while flights.in_progress() == 0 {
            tokio::task::yield_now().await;
        }
        first.abort();
        assert!(first.await.unwrap_err().is_cancelled());
        gate.add_permits(1);
        while found.load(Ordering::SeqCst) == 0 {
            tokio::task::yield_now().await;
        }
        assert_eq!(
            found.load(Ordering::SeqCst),
            2,
            "no one waited, yet it was wanted"
        );
        assert_eq!(flights.in_progress(), 0, "left on finding itself unwanted");
        // Left unwanted: a new request computes, and is wanted.
        let again = flights.get(1, || None, |wanted| async move { wanted.still() });
        assert!(again.await.unwrap());
    }
}
