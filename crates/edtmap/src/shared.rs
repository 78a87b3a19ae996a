//! [`SharedMapper`]: a mapper that one thread integrates into while others
//! query, for the bindings (Python, C) and the ROS 2 node, which hand a
//! mapper to several threads.
//!
//! Frames go in under a lock; queries read a [`Snapshot`] of the map as it
//! was after the last frame, published when the frame is done. Blocks are
//! shared copy-on-write, so taking a snapshot costs a pointer per block and
//! a query never waits for a frame, and always sees a whole one.

use std::ops::Deref;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, RwLock};

use crate::{FrameStats, GlobalMap, MapError, Mapper};
use edtmap_core::sensor::Frame;
use edtmap_core::{Backend, LocalVolume};

/// The map as the queries see it: the state after a whole frame. It
/// dereferences to its [`GlobalMap`].
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The map.
    pub map: GlobalMap,
    /// The latest frame's local volume, once a frame was mapped.
    pub volume: Option<LocalVolume>,
    /// Stamp of the latest frame integrated, nanoseconds (0 before any).
    pub stamp_ns: i64,
    /// Frames integrated.
    pub frames: u64,
}

impl Deref for Snapshot {
    type Target = GlobalMap;

    fn deref(&self) -> &GlobalMap {
        &self.map
    }
}

/// A [`Mapper`] behind a lock, and the snapshot its queries read.
#[derive(Debug)]
pub struct SharedMapper<B: Backend> {
    mapper: Mutex<Mapper<B>>,
    snapshot: RwLock<Arc<Snapshot>>,
}

impl<B: Backend> SharedMapper<B> {
    /// Shares `mapper`; the first snapshot is its map as it is.
    pub fn new(mapper: Mapper<B>) -> Self {
        let first =
            Snapshot { map: mapper.map().clone(), volume: mapper.local_volume().copied(), stamp_ns: 0, frames: 0 };
        SharedMapper { mapper: Mutex::new(mapper), snapshot: RwLock::new(Arc::new(first)) }
    }

    /// Integrates `frame` ([`Mapper::integrate_frame`]) and publishes the
    /// map it leaves for the queries.
    pub fn integrate(&self, frame: &Frame) -> Result<FrameStats, MapError> {
        self.integrate_sensor(0, frame)
    }

    /// [`Self::integrate`] of a frame of the mapper's sensor `index`
    /// ([`Mapper::integrate_sensor_frame`]).
    pub fn integrate_sensor(&self, index: usize, frame: &Frame) -> Result<FrameStats, MapError> {
        let mut mapper = self.lock()?;
        let stats = mapper.integrate_sensor_frame(index, frame)?;
        let frames = self.snapshot().frames + 1;
        self.publish(&mapper, stamp_ns(frame.stamp_s), frames);
        Ok(stats)
    }

    /// Publishes `mapper`'s map as it is now (the mapper [`Self::lock`]
    /// gave, after the `frames`-th frame, stamped `stamp_ns`) for the
    /// queries, and returns the snapshot.
    pub fn publish(&self, mapper: &Mapper<B>, stamp_ns: i64, frames: u64) -> Arc<Snapshot> {
        let snapshot =
            Arc::new(Snapshot { map: mapper.map().clone(), volume: mapper.local_volume().copied(), stamp_ns, frames });
        // The lock guards one pointer, whole whatever a panicking holder did.
        *self.snapshot.write().unwrap_or_else(PoisonError::into_inner) = snapshot.clone();
        snapshot
    }

    /// The map as it was after the last frame.
    pub fn snapshot(&self) -> Arc<Snapshot> {
        self.snapshot.read().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// The mapper itself, locked (frames wait; queries do not).
    pub fn lock(&self) -> Result<MutexGuard<'_, Mapper<B>>, MapError> {
        self.mapper.lock().map_err(|_| MapError::Poisoned("the mapper"))
    }
}

/// A frame's stamp in whole nanoseconds, as ROS stamps are.
fn stamp_ns(stamp_s: f64) -> i64 {
    (stamp_s * 1e9).round() as i64
}
