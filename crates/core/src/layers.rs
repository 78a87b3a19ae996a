//! A block's voxels stored by horizontal layer: a block whose voxels all
//! lie in one layer takes an eighth of the memory.
//!
//! A block is [`BLOCK_SIDE`]³ voxels, [`LAYERS`] layers of
//! [`LAYER_VOXELS`] along z. It holds nothing until a voxel first takes a
//! value other than the empty one ([`Cell::EMPTY`]: never observed, no
//! obstacle within the cutoff), then that voxel's layer alone, then, once a
//! second layer is written, all eight. A planar map's blocks hold one layer
//! of eight; a 3D map's blocks are whole arrays, read as before.
//!
//! Voxels are at [`crate::VoxelIndex::offset_in_block`], `x + 8 (y + 8 z)`,
//! so layer `z` holds offsets `64 z .. 64 z + 64`.

use crate::{BLOCK_SIDE, BLOCK_VOXELS};
use std::ops::Index;

/// Layers of a block, along z.
pub const LAYERS: usize = BLOCK_SIDE as usize;
/// Voxels in one layer of a block.
pub const LAYER_VOXELS: usize = BLOCK_VOXELS / LAYERS;

/// A value a block holds per voxel.
pub trait Cell: Copy + PartialEq + Send + Sync + 'static {
    /// The value of a voxel nothing has written.
    const EMPTY: Self;
    /// A layer of [`Self::EMPTY`], what an unallocated layer reads as.
    const EMPTY_LAYER: &'static [Self; LAYER_VOXELS];
}

/// A block's voxels: no layer, one layer, or the whole block.
///
/// A block with voxels in two layers or more holds all eight, as one
/// array: the voxels of a 3D map's blocks are then read as a plain array
/// is, with one predictable branch, and a block grows at most twice. A
/// planar map's blocks hold their one layer.
#[derive(Debug, Clone)]
pub struct Layers<T> {
    store: Store<T>,
}

impl<T> Default for Layers<T> {
    fn default() -> Self {
        Layers { store: Store::Empty }
    }
}

#[derive(Debug, Clone)]
enum Store<T> {
    /// Every voxel empty.
    Empty,
    /// Layer `z` alone; the others empty.
    One(u8, Box<[T; LAYER_VOXELS]>),
    /// Every layer, by offset.
    Full(Box<[T; BLOCK_VOXELS]>),
}

impl<T: Cell> PartialEq for Layers<T> {
    /// The same value in every voxel, however the layers are stored.
    fn eq(&self, other: &Self) -> bool {
        (0..LAYERS).all(|z| self.layer_or_empty(z) == other.layer_or_empty(z))
    }
}

impl<T: Cell> Index<usize> for Layers<T> {
    type Output = T;
    /// The value of the voxel at `offset` (below [`BLOCK_VOXELS`]).
    #[inline]
    fn index(&self, offset: usize) -> &T {
        match &self.store {
            Store::Full(all) => &all[offset],
            Store::One(z, layer) if usize::from(*z) == offset / LAYER_VOXELS => &layer[offset % LAYER_VOXELS],
            _ => &T::EMPTY_LAYER[offset % LAYER_VOXELS],
        }
    }
}

impl<T: Cell> Layers<T> {
    /// Layer `z`, if allocated.
    #[inline]
    pub fn layer(&self, z: usize) -> Option<&[T; LAYER_VOXELS]> {
        match &self.store {
            Store::Full(all) => all.as_chunks::<LAYER_VOXELS>().0.get(z),
            Store::One(k, layer) if usize::from(*k) == z => Some(layer),
            _ => None,
        }
    }

    /// Layer `z`, all [`Cell::EMPTY`] if not allocated.
    #[inline]
    pub fn layer_or_empty(&self, z: usize) -> &[T; LAYER_VOXELS] {
        self.layer(z).unwrap_or(T::EMPTY_LAYER)
    }

    /// Layer `z` (below [`LAYERS`]) to write, allocated (all
    /// [`Cell::EMPTY`]) if it was not.
    #[inline]
    pub fn layer_mut(&mut self, z: usize) -> &mut [T; LAYER_VOXELS] {
        let z = z % LAYERS;
        match &self.store {
            Store::Empty => self.store = Store::One(z as u8, Box::new(*T::EMPTY_LAYER)),
            Store::One(k, layer) if usize::from(*k) != z => {
                let mut all = Box::new([T::EMPTY; BLOCK_VOXELS]);
                all.as_chunks_mut::<LAYER_VOXELS>().0[usize::from(*k)] = **layer;
                self.store = Store::Full(all);
            }
            _ => {}
        }
        match &mut self.store {
            Store::Full(all) => &mut all.as_chunks_mut::<LAYER_VOXELS>().0[z],
            Store::One(_, layer) => layer,
            Store::Empty => unreachable!("a layer was just allocated"),
        }
    }

    /// Sets the voxel at `offset`; an empty value in an unallocated layer
    /// allocates nothing.
    #[inline]
    pub fn set(&mut self, offset: usize, value: T) {
        if let Store::Full(all) = &mut self.store {
            all[offset] = value;
        } else {
            self.set_in_part(offset, value);
        }
    }

    /// [`Self::set`] on a block not held whole.
    #[inline(never)]
    fn set_in_part(&mut self, offset: usize, value: T) {
        if value != T::EMPTY || self.layer(offset / LAYER_VOXELS).is_some() {
            self.layer_mut(offset / LAYER_VOXELS)[offset % LAYER_VOXELS] = value;
        }
    }

    /// The allocated layers, `(z, layer)`, ascending `z`.
    pub fn stored(&self) -> impl Iterator<Item = (usize, &[T; LAYER_VOXELS])> + '_ {
        (0..LAYERS).filter_map(|z| self.layer(z).map(|l| (z, l)))
    }

    /// Number of allocated layers.
    pub fn stored_layers(&self) -> usize {
        match self.store {
            Store::Empty => 0,
            Store::One(..) => 1,
            Store::Full(_) => LAYERS,
        }
    }

    /// Every voxel's value, in offset order.
    pub fn iter(&self) -> impl Iterator<Item = T> + '_ {
        (0..LAYERS).flat_map(move |z| self.layer_or_empty(z).iter().copied())
    }

    /// The voxels of the allocated layers, `(offset, value)`, ascending
    /// offset: every voxel not [`Cell::EMPTY`], and some that are.
    pub fn iter_stored(&self) -> impl Iterator<Item = (usize, T)> + '_ {
        self.stored().flat_map(|(z, l)| l.iter().enumerate().map(move |(i, &v)| (z * LAYER_VOXELS + i, v)))
    }

    /// Sets every voxel from `values` (by offset), keeping only the layers
    /// that hold a value other than [`Cell::EMPTY`].
    pub fn assign(&mut self, values: &[T; BLOCK_VOXELS]) {
        let layers = values.as_chunks::<LAYER_VOXELS>().0;
        let mut used = (0..LAYERS).filter(|&z| layers[z].iter().any(|&v| v != T::EMPTY));
        match (used.next(), used.next()) {
            (None, _) => self.store = Store::Empty,
            (Some(z), None) => self.store = Store::One(z as u8, Box::new(layers[z])),
            _ => match &mut self.store {
                Store::Full(all) => **all = *values,
                _ => self.store = Store::Full(Box::new(*values)),
            },
        }
    }

    /// Whether every voxel is [`Cell::EMPTY`].
    pub fn is_empty(&self) -> bool {
        self.stored().all(|(_, l)| l.iter().all(|&v| v == T::EMPTY))
    }

    /// Frees the block's voxels if every one is [`Cell::EMPTY`]; returns
    /// whether it did.
    pub fn trim(&mut self) -> bool {
        let empty = self.is_empty();
        if empty {
            self.store = Store::Empty;
        }
        empty
    }

    /// Bytes allocated for the voxels.
    pub fn heap_bytes(&self) -> usize {
        self.stored_layers() * std::mem::size_of::<[T; LAYER_VOXELS]>()
    }

    /// Asks for the allocated layers' cache lines without waiting for them.
    #[inline]
    pub fn prefetch(&self) {
        match &self.store {
            Store::Empty => {}
            Store::One(_, layer) => prefetch(&**layer),
            Store::Full(all) => prefetch(&**all),
        }
    }

    /// The voxels where `hit` holds, bit `o % 64` of word `o / 64` for the
    /// voxel at offset `o` (a layer not held as [`Cell::EMPTY`]; the test
    /// inlined, so it vectorises).
    #[inline]
    pub fn mask_where(&self, hit: impl Fn(T) -> bool) -> [u64; LAYERS] {
        let mut m = [if hit(T::EMPTY) { u64::MAX } else { 0 }; LAYERS];
        for (z, layer) in self.stored() {
            m[z] = layer.iter().enumerate().fold(0, |a, (i, &v)| a | u64::from(hit(v)) << i);
        }
        m
    }
}

/// Asks for every cache line of `value` without waiting for them, so that
/// blocks a task will read are loaded together rather than one miss at a
/// time.
#[inline]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p: *const i8 = std::ptr::from_ref(value).cast();
        for i in (0..std::mem::size_of::<T>()).step_by(64) {
            // SAFETY: a prefetch reads nothing the program sees and cannot
            // fault (the address is inside `value` anyway); SSE is part of
            // every x86-64.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(i)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    std::hint::black_box(value);
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Cell for u16 {
        const EMPTY: u16 = 0;
        const EMPTY_LAYER: &'static [u16; LAYER_VOXELS] = &[0; LAYER_VOXELS];
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 300, rng_seed: proptest::test_runner::RngSeed::Fixed(0x1A7E), ..Default::default() })]
        /// Layers agree with a plain array under any writes, whole
        /// assignments (of chosen layers) and trims, and hold no layer, one,
        /// or all.
        #[test]
        fn layers_read_as_the_array_written(
            ops in proptest::collection::vec((0u8..10, 0..BLOCK_VOXELS, 0u16..3, proptest::prelude::any::<u8>()), 0..40),
        ) {
            let mut plain = [0u16; BLOCK_VOXELS];
            let mut layers = Layers::<u16>::default();
            for (kind, o, v, mask) in ops {
                match kind {
                    0 => {
                        for (k, p) in plain.iter_mut().enumerate() {
                            let used = mask >> (k / LAYER_VOXELS) & 1 == 1;
                            *p = if used && (k * 7 + usize::from(v)) % 3 != 0 { v + 1 } else { 0 };
                        }
                        layers.assign(&plain);
                    }
                    1 => {
                        layers.trim();
                    }
                    _ => {
                        plain[o] = v;
                        layers.set(o, v);
                    }
                }
                proptest::prop_assert!(layers.iter().eq(plain.iter().copied()));
                proptest::prop_assert!((0..BLOCK_VOXELS).all(|o| layers[o] == plain[o]));
            }
            let empty = plain.iter().all(|&v| v == 0);
            proptest::prop_assert_eq!(layers.is_empty(), empty);
            proptest::prop_assert_eq!(layers.trim(), empty);
            let used = plain.chunks_exact(LAYER_VOXELS).filter(|l| l.iter().any(|&v| v != 0)).count();
            proptest::prop_assert!(layers.stored_layers() >= used && [0, 1, LAYERS].contains(&layers.stored_layers()));
            proptest::prop_assert!(layers.iter_stored().all(|(o, v)| plain[o] == v));
            let stored_nonempty = layers.iter_stored().filter(|&(_, v)| v != 0).count();
            proptest::prop_assert_eq!(stored_nonempty, plain.iter().filter(|&&v| v != 0).count());
            let mut fresh = Layers::<u16>::default();
            fresh.assign(&plain);
            proptest::prop_assert_eq!(&fresh, &layers);
            // Assigned, a block holds one layer only where one is used.
            proptest::prop_assert_eq!(fresh.stored_layers(), [0, 1].get(used).copied().unwrap_or(LAYERS));
        }
    }

    #[test]
    fn empty_writes_allocate_nothing() {
        let mut layers = Layers::<u16>::default();
        layers.set(70, 0);
        assert_eq!(layers.stored_layers(), 0);
        layers.set(70, 5);
        assert_eq!((layers.stored_layers(), layers.heap_bytes()), (1, 2 * LAYER_VOXELS));
        assert_eq!(layers.stored().map(|(z, _)| z).collect::<Vec<_>>(), vec![1]);
    }
}
