//! The configurations shipped in `configs/`, built in so that
//! `edtmap run --scene NAME` works from any folder.

/// The shipped configuration of a built-in scene.
pub(crate) fn builtin_config(scene: &str) -> Option<&'static str> {
    match scene {
        "uav_pillars" => Some(include_str!("../../../configs/uav_pillars.toml")),
        "ugv_corridor" => Some(include_str!("../../../configs/ugv_corridor.toml")),
        "room" => Some(include_str!("../../../configs/room.toml")),
        "planar" => Some(include_str!("../../../configs/planar.toml")),
        _ => None,
    }
}
