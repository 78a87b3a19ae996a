//! Errors of the scene simulator.

use edtmap_core::CoreError;
use thiserror::Error;

/// Errors raised when building a scene or simulating a frame.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum SimError {
    /// A scene option is out of its valid range.
    #[error("invalid scene option {field} = {value}: {reason}")]
    InvalidOption {
        /// The option's name.
        field: &'static str,
        /// The value given, as text.
        value: String,
        /// What the value must be.
        reason: &'static str,
    },
    /// No built-in scene has this name.
    #[error("unknown scene {name:?}: choose one of uav_pillars, ugv_corridor, room, planar")]
    UnknownScene {
        /// The name given.
        name: String,
    },
    /// The sensor would cast more rays per frame than the simulator allows.
    #[error("the sensor casts {rays} rays per frame, more than the limit of {limit}")]
    TooManyRays {
        /// Rays the sensor asks for.
        rays: u128,
        /// The most rays one frame may have.
        limit: usize,
    },
    /// The sensor's parameters are invalid.
    #[error(transparent)]
    Sensor(#[from] CoreError),
}
