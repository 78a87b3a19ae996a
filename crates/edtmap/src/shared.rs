//! [`SharedMapper`]: a mapper that one thread integrates into while others
//! query, for the bindings (Python, C) that hand a mapper to several
//! threads.
//!
//! Frames go in under a lock; queries read a snapshot of the map as it was
//! after the last frame, published when the frame is done. Blocks are
//! shared copy-on-write, so taking a snapshot costs a pointer per block and
//! a query never waits for a frame, and always sees a whole one.

use std::sync::{Arc, Mutex, MutexGuard, RwLock};

use crate::{FrameStats, GlobalMap, MapError, Mapper};
use edtmap_core::sensor::Frame;
use edtmap_core::Backend;

/// A [`Mapper`] behind a lock, and the snapshot its queries read.
#[derive(Debug)]
pub struct SharedMapper<B: Backend> {
    mapper: Mutex<Mapper<B>>,
    snapshot: RwLock<Arc<GlobalMap>>,
}

impl<B: Backend> SharedMapper<B> {
    /// Shares `mapper`; the first snapshot is its map as it is.
    pub fn new(mapper: Mapper<B>) -> Self {
        let snapshot = RwLock::new(Arc::new(mapper.map().clone()));
        SharedMapper { mapper: Mutex::new(mapper), snapshot }
    }

    /// Integrates `frame` ([`Mapper::integrate_frame`]) and publishes the
    /// map it leaves for the queries.
    pub fn integrate(&self, frame: &Frame) -> Result<FrameStats, MapError> {
        let mut mapper = self.lock()?;
        let stats = mapper.integrate_frame(frame)?;
        let map = Arc::new(mapper.map().clone());
        *self.snapshot.write().map_err(|_| MapError::Poisoned("the map snapshot"))? = map;
        Ok(stats)
    }

    /// The map as it was after the last frame.
    pub fn snapshot(&self) -> Result<Arc<GlobalMap>, MapError> {
        Ok(self.snapshot.read().map_err(|_| MapError::Poisoned("the map snapshot"))?.clone())
    }

    /// The mapper itself, locked (frames wait; queries do not).
    pub fn lock(&self) -> Result<MutexGuard<'_, Mapper<B>>, MapError> {
        self.mapper.lock().map_err(|_| MapError::Poisoned("the mapper"))
    }
}
