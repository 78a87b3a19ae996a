/// A buffer written concurrently by tasks that own disjoint voxels.
///
/// Scans along the strided axes split the volume into tiles of lines whose
/// voxels interleave in memory, so no safe slice split can hand each task
/// its tile. Every task reads and writes only the voxels of its own tile.
pub struct SharedBuf<T = u32> {
    ptr: *mut T,
    len: usize,
}

impl<T> Clone for SharedBuf<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for SharedBuf<T> {}

// SAFETY: `SharedBuf` is only a pointer and a length; the tasks that share it
// access disjoint indices (see the callers), so there are no data races.
unsafe impl<T: Send> Send for SharedBuf<T> {}
// SAFETY: as above.
unsafe impl<T: Send> Sync for SharedBuf<T> {}

impl<T: Copy> SharedBuf<T> {
    /// Shares `buf` for the duration of the tasks that write it.
    pub fn new(buf: &mut [T]) -> Self {
        SharedBuf { ptr: buf.as_mut_ptr(), len: buf.len() }
    }

    /// # Safety
    /// `i < len`, and no other task accesses index `i` concurrently.
    #[inline(always)]
    pub unsafe fn read(self, i: usize) -> T {
        debug_assert!(i < self.len);
        // SAFETY: guaranteed by the caller.
        unsafe { *self.ptr.add(i) }
    }

    /// # Safety
    /// `i < len`, and no other task accesses index `i` concurrently.
    #[inline(always)]
    pub unsafe fn write(self, i: usize, value: T) {
        debug_assert!(i < self.len);
        // SAFETY: guaranteed by the caller.
        unsafe { *self.ptr.add(i) = value }
    }
}
