//! A snapshot's values per triangle (the triangles, their objects, their
//! materials), in triangle-id order: a prefix shared by the snapshots of a
//! scene (its static triangles, which no animation moves) and the rest each
//! snapshot's own.
//!
//! Why: `trc` looks at the frames after the one it renders (the next one,
//! and later ones where lights move), each a whole snapshot, and every
//! snapshot held and placed its own copy of every static triangle. In a
//! room around a static sphere of 1.96M triangles under a sliding panel
//! light (`python3 benches/scenes/static_sphere.py 700 panel.glb
//! --moving-panel`, 64 × 64, 24 frames) that made `trc` 3.5× `ic`'s time,
//! most of it placing vertices and clearing fresh pages, and 4.4× its
//! memory (`benches/RESULTS.md`, "A large static scene under a moving
//! light"). Shared, a later snapshot costs what its moving triangles cost.

use std::ops::{Index, IndexMut, Range};
use std::sync::Arc;

/// Values `0..shared.len()` shared (behind an `Arc`), the rest owned.
/// The shared part is a slice, not a `Vec`, so its length and address sit
/// in this struct: an index is a comparison away from the value, as in a
/// `Vec` (the shading of every path vertex reads a triangle by id).
#[derive(Clone)]
pub struct Placed<T> {
    shared: Arc<[T]>,
    own: Vec<T>,
}

impl<T> Default for Placed<T> {
    fn default() -> Self {
        Placed {
            shared: Arc::new([]),
            own: Vec::new(),
        }
    }
}

impl<T> Placed<T> {
    /// `shared` followed by `own`.
    pub fn new(shared: Arc<[T]>, own: Vec<T>) -> Self {
        Placed { shared, own }
    }

    /// `values` with its first `n` made shareable (all of them where
    /// there are fewer).
    pub fn sharing_first(mut values: Vec<T>, n: usize) -> Self {
        let own = values.split_off(n.min(values.len()));
        Placed {
            shared: values.into(),
            own,
        }
    }

    pub fn len(&self) -> usize {
        self.shared.len() + self.own.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn get(&self, i: usize) -> Option<&T> {
        let s = self.shared.len();
        if i < s {
            self.shared.get(i)
        } else {
            self.own.get(i - s)
        }
    }

    /// Every value, in id order.
    pub fn iter(&self) -> std::iter::Chain<std::slice::Iter<'_, T>, std::slice::Iter<'_, T>> {
        self.shared.iter().chain(self.own.iter())
    }

    /// The values of ids `range`, in order.
    pub fn range(&self, range: Range<usize>) -> impl Iterator<Item = &T> + Clone + '_ {
        let (a, b) = self.parts();
        let cut = |len: usize, from: usize| {
            range.start.saturating_sub(from).min(len)..range.end.saturating_sub(from).min(len)
        };
        a[cut(a.len(), 0)]
            .iter()
            .chain(b[cut(b.len(), a.len())].iter())
    }

    /// The shared prefix and the owned rest.
    fn parts(&self) -> (&[T], &[T]) {
        (&self.shared, &self.own)
    }

    /// The shared prefix.
    pub fn shared(&self) -> &Arc<[T]> {
        &self.shared
    }

    /// Appends `value` to the owned part.
    pub fn push(&mut self, value: T) {
        self.own.push(value);
    }

    /// No values (the shared ones let go, not changed).
    pub fn clear(&mut self) {
        *self = Placed::default();
    }
}

impl<T: Clone> Placed<T> {
    /// Every value, in id order, in a vector of its own.
    pub fn to_vec(&self) -> Vec<T> {
        self.iter().cloned().collect()
    }

    /// The first `n` values, shared with `self` where they are its whole
    /// shared prefix (copied otherwise).
    pub fn prefix(&self, n: usize) -> Arc<[T]> {
        if self.shared.len() == n {
            self.shared.clone()
        } else {
            self.range(0..n).cloned().collect()
        }
    }

    /// Keeps the first `n` values.
    pub fn truncate(&mut self, n: usize) {
        if n < self.shared.len() {
            self.unshare();
        }
        self.own.truncate(n - self.shared.len());
    }

    /// Every value, mutably (all of them made this one's own first).
    pub fn iter_mut(&mut self) -> impl Iterator<Item = &mut T> {
        self.unshare();
        self.own.iter_mut()
    }

    /// Makes every value this one's own, none shared. A change is never
    /// made to a shared part, even one no other holder has: what was found
    /// of a shared part (`Snapshot::static_fingerprint`) holds while it
    /// is the same allocation.
    fn unshare(&mut self) {
        if !self.shared.is_empty() {
            let mut all = self.shared.to_vec();
            all.append(&mut self.own);
            self.own = all;
            self.shared = Arc::new([]);
        }
    }
}

impl<T> Index<usize> for Placed<T> {
    type Output = T;

    #[inline]
    fn index(&self, i: usize) -> &T {
        let s = self.shared.len();
        if i < s {
            &self.shared[i]
        } else {
            &self.own[i - s]
        }
    }
}

impl<T: Clone> IndexMut<usize> for Placed<T> {
    /// The value of id `i`, the shared ones made this one's own first.
    fn index_mut(&mut self, i: usize) -> &mut T {
        if i < self.shared.len() {
            self.unshare();
        }
        let s = self.shared.len();
        &mut self.own[i - s]
    }
}

impl<'a, T> IntoIterator for &'a Placed<T> {
    type Item = &'a T;
    type IntoIter = std::iter::Chain<std::slice::Iter<'a, T>, std::slice::Iter<'a, T>>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<T> From<Vec<T>> for Placed<T> {
    /// All of `values` owned, none shared.
    fn from(values: Vec<T>) -> Self {
        Placed {
            shared: Arc::new([]),
            own: values,
        }
    }
}

impl<T: std::fmt::Debug> std::fmt::Debug for Placed<T> {
    /// The values as one list, wherever the shared part ends.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T> FromIterator<T> for Placed<T> {
    /// All of them owned, none shared.
    fn from_iter<I: IntoIterator<Item = T>>(values: I) -> Self {
        Placed::from(values.into_iter().collect::<Vec<T>>())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ids index across the two parts as one sequence, ranges and prefixes
    /// cut it anywhere, and a change to a shared value leaves the other
    /// holder's as it was.
    #[test]
    fn the_two_parts_read_as_one_sequence() {
        let a = Placed::sharing_first((0..10).collect::<Vec<u32>>(), 4);
        assert_eq!(a.len(), 10);
        assert_eq!(
            (0..10).map(|i| a[i]).collect::<Vec<_>>(),
            (0..10).collect::<Vec<_>>()
        );
        assert_eq!(
            a.iter().copied().collect::<Vec<_>>(),
            (0..10).collect::<Vec<_>>()
        );
        for (lo, hi) in [(0, 10), (2, 4), (3, 7), (4, 9), (6, 6), (0, 4)] {
            let got: Vec<u32> = a.range(lo..hi).copied().collect();
            assert_eq!(
                got,
                (lo as u32..hi as u32).collect::<Vec<_>>(),
                "{lo}..{hi}"
            );
        }
        assert_eq!(a.get(10), None);
        assert!(
            Arc::ptr_eq(&a.prefix(4), &a.shared),
            "the whole prefix is shared"
        );
        assert_eq!(*a.prefix(6), vec![0, 1, 2, 3, 4, 5]);

        let mut b = Placed::new(a.prefix(4), vec![40, 50, 60]);
        b[1] = 100;
        assert_eq!(
            b.iter().copied().collect::<Vec<_>>(),
            vec![0, 100, 2, 3, 40, 50, 60]
        );
        assert_eq!(a[1], 1, "the other snapshot's shared value is unchanged");
        assert!(b.shared.is_empty(), "a change makes every value its own");
        b.truncate(2);
        assert_eq!(b.iter().copied().collect::<Vec<_>>(), vec![0, 100]);
        assert_eq!(a.len(), 10);
        let mut c = Placed::new(a.prefix(4), vec![]);
        c.truncate(3);
        assert_eq!(c.to_vec(), vec![0, 1, 2]);
        assert_eq!(a.to_vec(), (0..10).collect::<Vec<_>>());
    }
}
