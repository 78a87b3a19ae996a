/// A `u32` buffer written concurrently by tasks that own disjoint voxels.
///
/// Scans along the strided axes split the volume into tiles of lines whose
/// voxels interleave in memory, so no safe slice split can hand each task
/// its tile. Every task reads and writes only the voxels of its own tile.
#[derive(Clone, Copy)]
pub(super) struct SharedBuf {
    ptr: *mut u32,
    len: usize,
}

// SAFETY: `SharedBuf` is only a pointer and a length; the tasks that share it
// access disjoint indices (see the callers), so there are no data races.
unsafe impl Send for SharedBuf {}
// SAFETY: as above.
unsafe impl Sync for SharedBuf {}

impl SharedBuf {
    pub(super) fn new(buf: &mut [u32]) -> Self {
        SharedBuf { ptr: buf.as_mut_ptr(), len: buf.len() }
    }

    /// # Safety
    /// `i < len`, and no other task accesses index `i` concurrently.
    #[inline(always)]
    pub(super) unsafe fn read(self, i: usize) -> u32 {
        debug_assert!(i < self.len);
        // SAFETY: guaranteed by the caller.
        unsafe { *self.ptr.add(i) }
    }

    /// # Safety
    /// `i < len`, and no other task accesses index `i` concurrently.
    #[inline(always)]
    pub(super) unsafe fn write(self, i: usize, value: u32) {
        debug_assert!(i < self.len);
        // SAFETY: guaranteed by the caller.
        unsafe { *self.ptr.add(i) = value }
    }
}
