//! A block's voxels stored by horizontal layer: only the layers holding
//! something take memory.
//!
//! A block is [`BLOCK_SIDE`]³ voxels, [`LAYERS`] layers of
//! [`LAYER_VOXELS`] along z. A layer is allocated when a voxel of it first
//! takes a value other than the empty one ([`Cell::EMPTY`]: never observed,
//! no obstacle within the cutoff). A planar map's blocks hold one layer of
//! eight, so its blocks take an eighth of a full block's memory; a 3D map's
//! blocks at the edge of the observed space or of the cutoff keep only the
//! layers that reach into them.
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

/// An offset along one axis to the nearest obstacle, `i16::MIN` where
/// none lies within the cutoff (a stage of the separable EDT).
impl Cell for i16 {
    const EMPTY: i16 = i16::MIN;
    const EMPTY_LAYER: &'static [i16; LAYER_VOXELS] = &[i16::MIN; LAYER_VOXELS];
}

/// Offsets along two axes to the nearest obstacle, `i16::MIN` where none
/// lies within the cutoff (a stage of the separable EDT).
impl Cell for [i16; 2] {
    const EMPTY: [i16; 2] = [i16::MIN; 2];
    const EMPTY_LAYER: &'static [[i16; 2]; LAYER_VOXELS] = &[[i16::MIN; 2]; LAYER_VOXELS];
}

/// Slot of a layer not allocated.
const ABSENT: u8 = u8::MAX;

/// A block's voxels, allocated layer by layer.
#[derive(Debug, Clone)]
pub struct Layers<T> {
    /// Where layer `z` lies in `data`, [`ABSENT`] if not allocated.
    slot: [u8; LAYERS],
    /// The allocated layers, in the order they were allocated.
    data: Vec<[T; LAYER_VOXELS]>,
}

impl<T: Cell> Default for Layers<T> {
    fn default() -> Self {
        Layers { slot: [ABSENT; LAYERS], data: Vec::new() }
    }
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
        &self.layer_or_empty(offset / LAYER_VOXELS)[offset % LAYER_VOXELS]
    }
}

impl<T: Cell> Layers<T> {
    /// Layer `z`, if allocated.
    #[inline]
    pub fn layer(&self, z: usize) -> Option<&[T; LAYER_VOXELS]> {
        match self.slot[z] {
            ABSENT => None,
            s => Some(&self.data[usize::from(s)]),
        }
    }

    /// Layer `z`, all [`Cell::EMPTY`] if not allocated.
    #[inline]
    pub fn layer_or_empty(&self, z: usize) -> &[T; LAYER_VOXELS] {
        self.layer(z).unwrap_or(T::EMPTY_LAYER)
    }

    /// Layer `z` to write, allocated (all [`Cell::EMPTY`]) if it was not.
    #[inline]
    pub fn layer_mut(&mut self, z: usize) -> &mut [T; LAYER_VOXELS] {
        if self.slot[z] == ABSENT {
            // One layer more, not the doubling a `Vec` grows by: a planar
            // map's blocks hold one layer for good.
            self.data.reserve_exact(1);
            self.slot[z] = self.data.len() as u8;
            self.data.push(*T::EMPTY_LAYER);
        }
        &mut self.data[usize::from(self.slot[z])]
    }

    /// Sets the voxel at `offset`; an empty value in an unallocated layer
    /// allocates nothing.
    #[inline]
    pub fn set(&mut self, offset: usize, value: T) {
        let z = offset / LAYER_VOXELS;
        if value != T::EMPTY || self.slot[z] != ABSENT {
            self.layer_mut(z)[offset % LAYER_VOXELS] = value;
        }
    }

    /// The allocated layers, `(z, layer)`, ascending `z`.
    pub fn stored(&self) -> impl Iterator<Item = (usize, &[T; LAYER_VOXELS])> + '_ {
        (0..LAYERS).filter_map(|z| self.layer(z).map(|l| (z, l)))
    }

    /// The allocated layers, `(z, layer)`, to write, in no particular order.
    pub fn stored_mut(&mut self) -> impl Iterator<Item = (usize, &mut [T; LAYER_VOXELS])> + '_ {
        let mut z_of = [0; LAYERS];
        for (z, &s) in self.slot.iter().enumerate().filter(|(_, &s)| s != ABSENT) {
            z_of[usize::from(s)] = z;
        }
        self.data.iter_mut().zip(z_of).map(|(l, z)| (z, l))
    }

    /// Number of allocated layers.
    pub fn stored_layers(&self) -> usize {
        self.data.len()
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
        for (z, layer) in values.chunks_exact(LAYER_VOXELS).enumerate() {
            if layer.iter().all(|&v| v == T::EMPTY) {
                self.free(z);
            } else {
                self.layer_mut(z).copy_from_slice(layer);
            }
        }
    }

    /// Whether every voxel is [`Cell::EMPTY`].
    pub fn is_empty(&self) -> bool {
        self.data.iter().all(|l| l.iter().all(|&v| v == T::EMPTY))
    }

    /// Frees the layers that hold only [`Cell::EMPTY`]; returns whether
    /// none is left.
    pub fn trim(&mut self) -> bool {
        for z in 0..LAYERS {
            if self.layer(z).is_some_and(|l| l.iter().all(|&v| v == T::EMPTY)) {
                self.free(z);
            }
        }
        self.data.is_empty()
    }

    /// Frees layer `z`, which then reads as [`Cell::EMPTY`].
    fn free(&mut self, z: usize) {
        let s = self.slot[z];
        if s == ABSENT {
            return;
        }
        // The last layer takes the freed one's place.
        let last = (self.data.len() - 1) as u8;
        self.data.swap_remove(usize::from(s));
        if let Some(moved) = self.slot.iter_mut().find(|k| **k == last) {
            *moved = s;
        }
        self.slot[z] = ABSENT;
        if self.data.is_empty() {
            self.data = Vec::new();
        }
    }

    /// Bytes of the allocated layers.
    pub fn heap_bytes(&self) -> usize {
        self.data.capacity() * std::mem::size_of::<[T; LAYER_VOXELS]>()
    }

    /// Asks for the allocated layers' cache lines without waiting for them.
    #[inline]
    pub fn prefetch(&self) {
        #[cfg(target_arch = "x86_64")]
        for l in &self.data {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let p: *const i8 = std::ptr::from_ref(l).cast();
            for i in (0..std::mem::size_of::<[T; LAYER_VOXELS]>()).step_by(64) {
                // SAFETY: a prefetch reads nothing the program sees and
                // cannot fault (the address is inside the layer anyway);
                // SSE is part of every x86-64.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(i)) };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    impl Cell for u16 {
        const EMPTY: u16 = 0;
        const EMPTY_LAYER: &'static [u16; LAYER_VOXELS] = &[0; LAYER_VOXELS];
    }

    /// Layers agree with a plain array under any writes, and hold only the
    /// layers with a non-empty voxel once trimmed.
    #[test]
    fn layers_read_as_the_array_written() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move |n: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % n
        };
        for _ in 0..200 {
            let mut plain = [0u16; BLOCK_VOXELS];
            let mut layers = Layers::<u16>::default();
            for _ in 0..next(40) {
                let (o, v) = (next(BLOCK_VOXELS as u64) as usize, next(3) as u16);
                match next(10) {
                    0 => {
                        let all: Vec<u16> = (0..BLOCK_VOXELS).map(|_| next(2) as u16 * next(4) as u16).collect();
                        let all: [u16; BLOCK_VOXELS] = all.try_into().expect("512");
                        plain = all;
                        layers.assign(&all);
                    }
                    1 => {
                        layers.trim();
                    }
                    _ => {
                        plain[o] = v;
                        layers.set(o, v);
                    }
                }
                assert!(layers.iter().eq(plain.iter().copied()));
                assert!((0..BLOCK_VOXELS).all(|o| layers[o] == plain[o]));
            }
            let empty = plain.iter().all(|&v| v == 0);
            assert_eq!(layers.is_empty(), empty);
            assert_eq!(layers.trim(), empty);
            let used = plain.chunks_exact(LAYER_VOXELS).filter(|l| l.iter().any(|&v| v != 0)).count();
            assert_eq!(layers.stored_layers(), used);
            assert!(layers.iter_stored().all(|(o, v)| plain[o] == v));
            assert_eq!(
                layers.iter_stored().filter(|&(_, v)| v != 0).count(),
                plain.iter().filter(|&&v| v != 0).count()
            );
            let mut written: Vec<usize> = layers.stored_mut().map(|(z, _)| z).collect();
            written.sort_unstable();
            assert_eq!(written, layers.stored().map(|(z, _)| z).collect::<Vec<_>>());
            let mut fresh = Layers::<u16>::default();
            fresh.assign(&plain);
            assert_eq!(fresh, layers);
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
