//! The scene's tap on its own queries: about one query in 64, chosen by a hash of the ray (so
//! threads share no counter to choose), is copied into a fixed buffer until the buffer is full.
//! [`crate::Scene::update`] traces those rays through the structures to correct a decision made
//! on the library's sample rays, which see the scene from outside and may not look like the
//! renderer's rays (a camera inside a building, short occlusion rays). Each `update` that measures
//! the tapped rays starts the buffer over, so that every batch of queries is judged on its own.
//!
//! Queries never allocate: the buffer is taken when the scene is built. A query that is tapped
//! reserves a slot with one atomic add and writes its ray there; the buffer is read only by
//! `update`, which holds the scene exclusively (`&mut`), so no query can be writing then.

use alloc::vec::Vec;
use core::cell::UnsafeCell;
#[cfg(target_has_atomic = "ptr")]
use core::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;

use crate::budget::{bytes_of, MemoryBudget};
use crate::error::BuildError;
use crate::ray::Ray;
use crate::select::model::SceneFeatures;

/// Rays the tap holds: enough for an estimate as good as the library's own samples (up to 1 152).
pub const TAP_RAYS: usize = 1024;

/// Fewer tapped rays than this say too little to overrule the library's samples.
pub const TAP_MIN_RAYS: usize = 256;

/// One ray in `2^TAP_SHIFT` is tapped (by its hash).
const TAP_SHIFT: u32 = 6;

/// A fixed buffer of tapped rays.
pub struct QueryTap {
    rays: Vec<UnsafeCell<Ray>>,
    /// What the first `n` tapped rays did on the grid, once measured (`n`, features).
    pub measured: Option<(usize, SceneFeatures)>,
    /// Whether the batch measured last asked for the kd-tree: [`crate::Scene::update`] switches
    /// only when the next batch's rays, tapped afresh, ask too.
    pub asked: bool,
    /// Whether a batch was measured since the tap was taken (or cleared): from then on the scene's
    /// estimate is the tapped rays', and a switch waits for a measured batch to agree.
    pub heard: bool,
    /// Slots reserved so far (may pass `rays.len()`: later offers are dropped).
    #[cfg(target_has_atomic = "ptr")]
    next: AtomicUsize,
}

// SAFETY: a slot is written only by the query that reserved it with `fetch_add` (each index is
// handed out once), and read only through `&mut QueryTap`, when no query can be running.
unsafe impl Sync for QueryTap {}

impl core::fmt::Debug for QueryTap {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("QueryTap")
            .field("capacity", &self.rays.len())
            .finish()
    }
}

impl QueryTap {
    /// An empty tap of [`TAP_RAYS`] rays, charged to `budget`. `None` on targets without atomic
    /// adds (the tap then never takes a ray).
    pub fn new(budget: &mut MemoryBudget) -> Result<Option<QueryTap>, BuildError> {
        if !cfg!(target_has_atomic = "ptr") {
            return Ok(None);
        }
        let mut rays = budget.vec(TAP_RAYS, "query tap")?;
        rays.extend((0..TAP_RAYS).map(|_| UnsafeCell::new(Ray::new(Vec3::ZERO, Vec3::ZERO))));
        Ok(Some(QueryTap {
            rays,
            measured: None,
            asked: false,
            heard: false,
            #[cfg(target_has_atomic = "ptr")]
            next: AtomicUsize::new(0),
        }))
    }

    /// Takes `ray` if its hash picks it and there is room. Never blocks, never allocates.
    #[inline]
    pub fn offer(&self, ray: &Ray) {
        #[cfg(target_has_atomic = "ptr")]
        {
            // Relaxed: the slot index only has to be unique; `update`'s exclusive borrow orders
            // the writes before the reads. A full tap costs a query one load of a line that no
            // thread writes any more.
            if self.next.load(Ordering::Relaxed) >= self.rays.len() || !picked(ray) {
                return;
            }
            let i = self.next.fetch_add(1, Ordering::Relaxed);
            if let Some(slot) = self.rays.get(i) {
                // SAFETY: `fetch_add` gave index `i` to this call alone, so no other thread
                // writes this slot, and none reads it while queries may run (see `Sync`).
                unsafe { *slot.get() = *ray };
            }
        }
        #[cfg(not(target_has_atomic = "ptr"))]
        let _ = ray;
    }

    /// The rays taken so far.
    pub fn rays(&mut self) -> &[Ray] {
        let n = self.taken();
        let taken = self.rays.get_mut(..n).unwrap_or_default();
        // SAFETY: `UnsafeCell<Ray>` has the layout of `Ray`, and the exclusive borrow of `self`
        // (held for as long as the slice lives) means no query writes these slots meanwhile.
        unsafe { core::slice::from_raw_parts(taken.as_ptr() as *const Ray, taken.len()) }
    }

    /// How many rays the tap holds.
    pub fn taken(&mut self) -> usize {
        #[cfg(target_has_atomic = "ptr")]
        let n = *self.next.get_mut();
        #[cfg(not(target_has_atomic = "ptr"))]
        let n = 0;
        n.min(self.rays.len())
    }

    /// Forgets the rays taken and what batches said, to collect new ones.
    pub fn clear(&mut self) {
        self.asked = false;
        self.heard = false;
        self.next_batch();
    }

    /// Forgets the rays taken (not what batches said), so that the next batch's rays are the ones
    /// tapped.
    pub fn next_batch(&mut self) {
        self.measured = None;
        #[cfg(target_has_atomic = "ptr")]
        {
            *self.next.get_mut() = 0;
        }
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        bytes_of(&self.rays)
    }
}

/// Whether the tap takes `ray`: the top bits of a multiplicative hash of its origin and direction,
/// so about one ray in 64 of any varied workload, the same ray always the same way.
#[inline(always)]
#[cfg_attr(not(target_has_atomic = "ptr"), allow(dead_code))]
fn picked(ray: &Ray) -> bool {
    let b = |x: f32| x.to_bits();
    let h = b(ray.org.x)
        ^ b(ray.org.y).rotate_left(7)
        ^ b(ray.org.z).rotate_left(14)
        ^ b(ray.dir.x).rotate_left(19)
        ^ b(ray.dir.y).rotate_left(25)
        ^ b(ray.dir.z).rotate_left(29);
    h.wrapping_mul(0x9E37_79B1) >> (32 - TAP_SHIFT) == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::SplitMix64;

    fn rays(n: usize, seed: u64) -> alloc::vec::Vec<Ray> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| Ray::new(rng.next_vec3(), rng.unit_vector()))
            .collect()
    }

    /// The tap keeps exactly the picked rays, in the order offered, up to its size; clearing it
    /// starts over.
    #[test]
    fn keeps_the_picked_rays_up_to_its_size() {
        let mut tap = QueryTap::new(&mut MemoryBudget::new(0)).unwrap().unwrap();
        let offered = rays(if cfg!(miri) { 2_000 } else { 200_000 }, 3);
        for r in &offered {
            tap.offer(r);
        }
        let picked: alloc::vec::Vec<Ray> = offered.iter().filter(|r| picked(r)).copied().collect();
        // About one in 64.
        let expect = offered.len() / 64;
        assert!(picked.len() > expect / 2 && picked.len() < expect * 2);
        let n = picked.len().min(TAP_RAYS);
        assert_eq!(tap.taken(), n);
        assert_eq!(tap.rays(), &picked[..n]);
        tap.clear();
        assert_eq!(tap.taken(), 0);
        assert!(tap.rays().is_empty());
    }

    /// Offers from several threads at once fill distinct slots (what Miri checks for races).
    #[cfg(feature = "std")]
    #[test]
    fn threads_share_a_tap() {
        extern crate std;
        let mut tap = QueryTap::new(&mut MemoryBudget::new(0)).unwrap().unwrap();
        let per_thread = if cfg!(miri) { 500 } else { 20_000 };
        let sets: alloc::vec::Vec<_> = (0..4).map(|t| rays(per_thread, 10 + t)).collect();
        std::thread::scope(|s| {
            for set in &sets {
                let tap = &tap;
                s.spawn(move || set.iter().for_each(|r| tap.offer(r)));
            }
        });
        let chosen = sets.iter().flatten().filter(|r| picked(r)).count();
        assert_eq!(tap.taken(), chosen.min(TAP_RAYS));
        let mut got: alloc::vec::Vec<Ray> = tap.rays().to_vec();
        for r in sets.iter().flatten().filter(|r| picked(r)) {
            if let Some(i) = got.iter().position(|g| g == r) {
                got.swap_remove(i);
            }
        }
        assert!(got.is_empty(), "the tap holds rays nobody offered");
    }
}
